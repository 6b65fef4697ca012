"""numba keys a cached kernel on its own source file, so a kernel calling one in another module could run
stale machine code after that module changed. Every teleprev kernel is cached under the whole package's
hash instead: a change to any kernel module invalidates them all."""

import importlib
import pkgutil
import shutil

from numba.core.registry import CPUDispatcher

import teleprev.kernels
from teleprev.kernels import package_stamp


def test_every_kernel_is_cached_under_the_package_hash():
    kernels = [f for m in pkgutil.iter_modules(teleprev.kernels.__path__)
               for f in vars(importlib.import_module("teleprev.kernels." + m.name)).values()
               if isinstance(f, CPUDispatcher)]
    assert len(kernels) > 30
    for kernel in kernels:
        assert kernel._cache._impl._locator.get_source_stamp() == package_stamp(), kernel.__name__


def test_the_package_hash_changes_with_any_module(tmp_path, monkeypatch):
    """The same hash function over a copy of the package, one module edited: another stamp."""
    real = package_stamp()
    copy = tmp_path / "kernels"
    shutil.copytree(teleprev.kernels.__path__[0], copy, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(teleprev.kernels, "_HERE", str(copy))
    monkeypatch.setattr(teleprev.kernels, "_STAMP", [])
    same = package_stamp()
    assert same == real  # the same files give the same stamp
    (copy / "boxes.py").write_text((copy / "boxes.py").read_text() + "\n# edited\n")
    monkeypatch.setattr(teleprev.kernels, "_STAMP", [])
    assert package_stamp() != same
