"""Every kernel takes the fields of its tables in their order: a kernel's parameters are what its module's
SIGNATURES says, each table standing for its fields (callers pass `*table`, so an order that drifted would
hand a kernel one array for another)."""

import importlib
import inspect
import pkgutil

import pytest

import teleprev.kernels

MODULES = [
    importlib.import_module("teleprev.kernels." + m.name) for m in pkgutil.iter_modules(teleprev.kernels.__path__)
]


def _expanded(layout: tuple) -> list[str]:
    out = []
    for part in layout:
        out += list(part._fields) if isinstance(part, type) else [part]
    return out


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.__name__.rsplit(".", 1)[1])
def test_each_kernel_takes_its_tables_fields_in_order(module):
    if module.__name__.endswith((".boxes",)):  # inline helpers only: no tables
        assert not hasattr(module, "SIGNATURES")
        return
    assert module.SIGNATURES, module.__name__
    for name, layout in module.SIGNATURES.items():
        kernel = getattr(module, name)
        params = list(inspect.signature(kernel.py_func).parameters)
        assert params == _expanded(layout), name


def test_the_tables_fields_are_what_their_classes_build():
    """The classes build their tables by field name, so a renamed field fails here, not in a kernel."""
    from teleprev.kernels.collision import BoxTable, Margins
    from teleprev.kernels.fk import FkTable
    from teleprev.robot.collision import SelfCollisionChecker
    from teleprev.robot.model import load_robot

    checker = SelfCollisionChecker(load_robot("leap_hand_right"))
    fk, boxes, margins = checker.kernel_tables
    assert isinstance(fk, FkTable) and isinstance(boxes, BoxTable) and isinstance(margins, Margins)
    assert margins.loose > 0 > margins.tight
