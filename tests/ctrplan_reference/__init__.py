"""Frozen slow reference implementations of the mechanics (see each module's docstring)."""
