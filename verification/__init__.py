"""Checks of an estimate: cross-checks, simulation studies, accuracy reports, plots."""
