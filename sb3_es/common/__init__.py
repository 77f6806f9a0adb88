"""Shared core: flat-parameter policies and the SB3 glue of the population algorithms."""
