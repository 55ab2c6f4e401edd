"""Source-seeking strategies and runners. Not implemented yet: see issue 6."""
