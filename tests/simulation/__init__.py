"""Deterministic simulation of the whole client stack (issue 22): see world.py."""
