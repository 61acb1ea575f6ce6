"""Estimators: point-set registration, closed-form CPC identification, hand-eye, refinement."""
