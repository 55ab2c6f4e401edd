"""Wind estimator (paper Eq. 49-53). Not implemented yet: see issue 4."""
