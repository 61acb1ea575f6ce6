"""Checks of an estimate, the layer above :mod:`kinfw.identification`.

:mod:`kinfw.verification.evaluation` (errors against data, cross-validation, model
choice, Cramér-Rao bound, cross-check), :mod:`kinfw.verification.reporting` (a
calibration's report and files), :mod:`kinfw.verification.studies` (simulation studies and
the demo) and :mod:`kinfw.verification.papers` (the papers' experiments). This package
itself exports nothing: import from the subpackages, or the workflow verbs from
:mod:`kinfw`.
"""
