"""windseek command-line entry point."""
