"""The house's rules, read from the source: one installed namespace, layers that import
downwards only, subpackage faces with one public import path per name.

The truth here is the tree itself (parsed with :mod:`ast` once per module, nothing
imported but the faces): each rule is one test over every module, and a rule broken by
new modules fails with every file and import that breaks it, in one message.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest
import tomllib

from tests.paths import REPO

#: The founding folders and the names they install as.
FOLDERS = {
    "kinfw": "kinfw",
    "identification": "kinfw.identification",
    "verification": "kinfw.verification",
}


def _modules() -> dict[str, Path]:
    """Every library module by its installed dotted name."""
    out = {}
    for folder, package in FOLDERS.items():
        for path in sorted((REPO / folder).rglob("*.py")):
            parts = list(path.relative_to(REPO / folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([package, *parts])] = path
    return out


MODULES = _modules()


def _imports(tree: ast.Module) -> list[tuple[int, str]]:
    """``(line, module)`` of every absolute import in a parsed file, function bodies
    included."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.append((node.lineno, node.module))
        elif isinstance(node, ast.Import):
            out.extend((node.lineno, alias.name) for alias in node.names)
    return out


#: Every library module's parsed source, read once for every rule below.
TREES = {name: ast.parse(path.read_text()) for name, path in MODULES.items()}

#: ``(line, module)`` of every absolute import, by importing module.
IMPORTS = {name: _imports(tree) for name, tree in TREES.items()}


def _offenders(found: list[str]) -> str:
    """One message naming every offending ``file:line: import``."""
    return f"{len(found)} offending (file:line: import):\n" + "\n".join(found)


def _layer(module: str) -> str:
    for layer in ("kinfw.identification", "kinfw.verification", "kinfw.cli"):
        if module == layer or module.startswith(layer + "."):
            return layer
    return "kinfw"


def test_the_packages_listed_for_installation_are_the_tree():
    listed = set(
        tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]
    )
    packages = {name for name, path in MODULES.items() if path.name == "__init__.py"}
    assert listed == packages | {"kinfw.robots"}


def test_the_library_imports_only_its_one_namespace():
    """No ``import identification`` / ``verification``: they exist only as kinfw.*."""
    bare = [
        f"{MODULES[name]}:{line}: {module}"
        for name in sorted(MODULES)
        for line, module in IMPORTS[name]
        if module.split(".")[0] in ("identification", "verification", "robots")
    ]
    assert not bare, _offenders(bare)


# What each layer may import. The front door (kinfw/__init__.py) names the workflow verbs
# of every layer, imported on first use; the command line sits on top of everything.
ALLOWED = {
    "kinfw": {"kinfw"},
    "kinfw.identification": {"kinfw", "kinfw.identification"},
    "kinfw.verification": {"kinfw", "kinfw.identification", "kinfw.verification"},
    "kinfw.cli": {"kinfw", "kinfw.identification", "kinfw.verification", "kinfw.cli"},
}


def test_layers_import_downwards_only():
    upward = [
        f"{MODULES[name]}:{line}: imports {module}"
        for name in sorted(n for n in MODULES if n != "kinfw")
        for line, module in IMPORTS[name]
        if module.startswith("kinfw") and _layer(module) not in ALLOWED[_layer(name)]
    ]
    assert not upward, _offenders(upward)


def _faces() -> dict[str, list[str]]:
    """``__all__`` of every subpackage face (its ``__init__``)."""
    return {
        name: list(getattr(importlib.import_module(name), "__all__", ()))
        for name, path in MODULES.items()
        if path.name == "__init__.py" and name != "kinfw"
    }


def test_every_public_name_has_one_import_path():
    """A name in two faces' ``__all__`` has two import paths; the front door ``kinfw`` is
    the one documented exception (its verbs are aliases of their homes)."""
    homes: dict[str, list[str]] = {}
    for face, names in _faces().items():
        for n in names:
            homes.setdefault(n, []).append(face)
    assert {n: f for n, f in homes.items() if len(f) > 1} == {}


def test_faces_export_only_what_their_package_defines():
    """A face re-exports its own private modules, never another package's names."""
    foreign = {}
    for face, names in _faces().items():
        package = importlib.import_module(face)
        for n in names:
            home = getattr(getattr(package, n), "__module__", face) or face
            if not callable(getattr(package, n)) or not home.startswith("kinfw"):
                continue  # constants and type aliases: checked through their one face above
            if not (home == face or home.startswith(face + ".")):
                foreign[f"{face}.{n}"] = home
    assert foreign == {}


def test_no_private_module_is_imported_from_another_package():
    """``from kinfw.geometry._transforms import x`` belongs inside kinfw.geometry only."""
    crossing = []
    for name in sorted(MODULES):
        path = MODULES[name]
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        for line, module in IMPORTS[name]:
            parts = module.split(".")
            private = [i for i, p in enumerate(parts) if p.startswith("_")]
            if module.startswith("kinfw") and private:
                owner = ".".join(parts[: private[0]])
                if owner != package:
                    crossing.append(f"{path}:{line}: {module}")
    assert not crossing, _offenders(crossing)


@pytest.mark.slow
def test_the_wheel_installs_one_namespace(tmp_path):
    """``pip install .`` puts ``kinfw`` (and the built-in URDF) in site-packages and no
    top-level ``identification`` / ``verification`` / ``robots``: read from the wheel pip
    builds from this tree."""
    import shutil
    import subprocess
    import sys
    import zipfile

    source = tmp_path / "source"  # a copy: setuptools writes build/ beside the sources
    source.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO / name, source / name)
    for folder in (*FOLDERS, "robots"):
        shutil.copytree(
            REPO / folder, source / folder, ignore=shutil.ignore_patterns("__pycache__")
        )
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(tmp_path), str(source)],
        check=True,
        capture_output=True,
    )
    (wheel,) = tmp_path.glob("kinfw-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert {n.split("/")[0] for n in names} == {"kinfw", wheel.name.split("-py")[0] + ".dist-info"}
    assert "kinfw/robots/iis_head.urdf" in names
    assert "kinfw/identification/_pipeline.py" in names
    assert "kinfw/verification/evaluation/__init__.py" in names


def test_no_private_name_is_imported_from_another_module():
    """``from kinfw.x._m import _helper`` hides a shared helper under a private name: a
    name used by two modules is a name of its package (without the underscore)."""
    private = [
        f"{MODULES[name]}:{node.lineno}: {alias.name} from {node.module}"
        for name in sorted(MODULES)
        for node in ast.walk(TREES[name])
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("kinfw")
        for alias in node.names
        if alias.name.startswith("_")
    ]
    assert not private, _offenders(private)


def test_private_modules_define_no_all():
    """A private module (``_name.py``) is read through its package's face, so a name is
    written twice at most (the face's import and its ``__all__``): ``__all__`` belongs
    to faces alone."""
    listed = [
        f"{MODULES[name]}:{node.lineno}: __all__"
        for name in sorted(MODULES)
        if MODULES[name].name.startswith("_") and MODULES[name].name != "__init__.py"
        for node in TREES[name].body
        if isinstance(node, ast.Assign | ast.AnnAssign | ast.AugAssign)
        for target in (node.targets if isinstance(node, ast.Assign) else [node.target])
        if isinstance(target, ast.Name) and target.id == "__all__"
    ]
    assert not listed, _offenders(listed)
