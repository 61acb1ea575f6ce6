"""kinfw: calibrate robot kinematics from measurements.

The front door: the workflow in a dozen verbs, each an alias of its home in a subpackage
(the layers below), imported on first use::

    import kinfw

    nominal = kinfw.load_robot("robot.urdf")            # kinfw.model
    data = kinfw.read_measurements("data.json")         # kinfw.measurements
    result = kinfw.calibrate(nominal, data)             # kinfw.verification.reporting
    result.write("calibrated.urdf")                     # + calibrated.kinfw.json
    kinfw.evaluate(result.robot, kinfw.read_measurements("held_out.json"))

=====================  ==================================================================
verb                   home
=====================  ==================================================================
``load_robot``         :func:`kinfw.model.load_robot` (a URDF path or URDF text)
``builtin_head_urdf``  :func:`kinfw.model.builtin_head_urdf` (the IIS-head's URDF path)
``read_measurements``  :func:`kinfw.measurements.read_measurements`
``write_measurements`` :func:`kinfw.measurements.write_measurements`
``calibrate``          :func:`kinfw.verification.reporting.calibrate_and_report`
``evaluate``           :func:`kinfw.verification.evaluation.evaluate_model`
``crossvalidate``      :func:`kinfw.verification.evaluation.crossvalidate`
``simulate``           :func:`kinfw.simulation.simulate_measurements`
``plan``               :func:`kinfw.identification.planning.plan_measurement`
``show``               :func:`kinfw.view.show` (live on 127.0.0.1, or an HTML file)
``fixate``             :func:`kinfw.control.fixate`
``reach``              :func:`kinfw.control.reach`
``solve_axxb``         :func:`kinfw.identification.handeye.solve_axxb`
``solve_axyb``         :func:`kinfw.identification.handeye.solve_axyb`
=====================  ==================================================================

Each ``kinfw`` command is a thin layer over one of these (or another verb of the same
homes): ``kinfw calibrate`` over :func:`calibrate`, ``simulate`` over :func:`simulate`,
``plan`` over :func:`plan`, ``crossval`` over :func:`crossvalidate`, ``verify`` over
:func:`evaluate`, ``view`` over :func:`show`, ``gaze`` over :func:`fixate`, ``reach``
over :func:`reach`; with the same defaults.

The verbs take loaded objects: a :class:`kinfw.model.Robot` and
:class:`kinfw.measurements.Measurements`, not paths (``calibrate``, ``simulate`` and
``plan`` raise a TypeError naming the argument when given one; load it with
``load_robot`` / ``read_measurements``). ``show`` alone also takes URDF paths, as the
view does. Types, exceptions and every other function have one import path, their
subpackage's face (``from kinfw.model import Robot``, ``from kinfw.observations import
DatasetError``).

``import kinfw`` loads neither numpy, Pinocchio, CasADi, meshcat nor matplotlib: a verb's
home is imported when the verb is first used (PEP 562), so ``import kinfw.cli`` (which
runs this file) stays light and ``kinfw --help`` starts at once.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from kinfw.control import fixate, reach
    from kinfw.identification.handeye import solve_axxb, solve_axyb
    from kinfw.identification.planning import plan_measurement as plan
    from kinfw.measurements import read_measurements, write_measurements
    from kinfw.model import builtin_head_urdf, load_robot
    from kinfw.simulation import simulate_measurements as simulate
    from kinfw.verification.evaluation import crossvalidate
    from kinfw.verification.evaluation import evaluate_model as evaluate
    from kinfw.verification.reporting import calibrate_and_report as calibrate
    from kinfw.view import show

#: Each verb: ``(home module, name there)``.
_HOME = {
    "load_robot": ("kinfw.model", "load_robot"),
    "builtin_head_urdf": ("kinfw.model", "builtin_head_urdf"),
    "read_measurements": ("kinfw.measurements", "read_measurements"),
    "write_measurements": ("kinfw.measurements", "write_measurements"),
    "calibrate": ("kinfw.verification.reporting", "calibrate_and_report"),
    "evaluate": ("kinfw.verification.evaluation", "evaluate_model"),
    "crossvalidate": ("kinfw.verification.evaluation", "crossvalidate"),
    "simulate": ("kinfw.simulation", "simulate_measurements"),
    "plan": ("kinfw.identification.planning", "plan_measurement"),
    "show": ("kinfw.view", "show"),
    "fixate": ("kinfw.control", "fixate"),
    "reach": ("kinfw.control", "reach"),
    "solve_axxb": ("kinfw.identification.handeye", "solve_axxb"),
    "solve_axyb": ("kinfw.identification.handeye", "solve_axyb"),
}

_SUBMODULES = ("geometry", "measurements", "model", "urdf")


def __getattr__(name: str) -> Any:
    if name in _SUBMODULES:  # ``import kinfw; kinfw.model`` as before the lazy loading
        return importlib.import_module(f"kinfw.{name}")
    if name not in _HOME:
        raise AttributeError(f"module 'kinfw' has no attribute {name!r}")
    module, home_name = _HOME[name]
    value = getattr(importlib.import_module(module), home_name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_HOME})


__all__ = [
    "builtin_head_urdf",
    "calibrate",
    "crossvalidate",
    "evaluate",
    "fixate",
    "load_robot",
    "plan",
    "reach",
    "read_measurements",
    "show",
    "simulate",
    "solve_axxb",
    "solve_axyb",
    "write_measurements",
]
