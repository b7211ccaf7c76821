"""The packages' lazily exported entry points (``lazy_loader.attach``, as scikit-image does)."""

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

import kitegully

LAZY_PACKAGES = sorted(init.parent.name for init in Path(kitegully.__path__[0]).glob("*/__init__.py")
                       if "lazy_loader.attach" in init.read_text(encoding="utf-8"))


def test_the_stage_packages_export_lazily():
    assert {"change", "gully", "polygons", "stereo", "twin"} <= set(LAZY_PACKAGES)


@pytest.mark.parametrize("name", LAZY_PACKAGES)
def test_every_exported_name_resolves(name):
    package = importlib.import_module(f"kitegully.{name}")
    assert package.__all__ == sorted(package.__all__) and package.__all__
    for attr in package.__all__:
        assert getattr(package, attr) is not None, f"kitegully.{name}.{attr}"
    assert set(dir(package)) == set(package.__all__)
    with pytest.raises(AttributeError):
        getattr(package, "no_such_entry_point")


def test_importing_a_package_does_not_import_its_stage():
    # the Snakefile imports packages to validate a config; the stages (and what they import)
    # must load only when a rule asks for them
    code = ("import sys, kitegully.gully, kitegully.polygons, kitegully.change; "
            "print(sorted(m for m in sys.modules if m.startswith('kitegully.')))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    for stage in ("kitegully.gully.pipeline", "kitegully.polygons.stage", "kitegully.change.stage"):
        assert stage not in loaded
