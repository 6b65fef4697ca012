"""The public device API: plugins import teleprev only through `teleprev.devices`, and that module holds
the whole contract (typed settings, topic naming, the optional SDK) while staying light to import."""

from __future__ import annotations

import ast
import dataclasses
import subprocess
import sys
from pathlib import Path

import pytest

import teleprev.devices as api
from teleprev.devices import KINDS, Device, DeviceContext, DeviceError, Sample, SessionClock, StreamSpec, available

PLUGINS = Path(__file__).resolve().parents[2] / "devices" / "teleprev_devices"


def teleprev_imports(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every absolute import of teleprev code in a file, in functions too."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            # `from teleprev import transforms` imports teleprev.transforms
            found += [
                (node.lineno, f"teleprev.{a.name}" if node.module == "teleprev" else node.module) for a in node.names
            ]
    return [(line, m) for line, m in found if m == "teleprev" or m.startswith("teleprev.")]


def test_plugins_import_nothing_of_teleprev_but_the_public_api():
    modules = sorted(PLUGINS.rglob("*.py"))
    assert len(modules) > 20
    outside = [f"{p.relative_to(PLUGINS.parent)}:{line} imports {m}"
               for p in modules for line, m in teleprev_imports(p) if m != "teleprev.devices"]
    assert not outside, "plugins must import teleprev only through teleprev.devices:\n" + "\n".join(outside)


def test_everything_the_api_lists_is_there():
    missing = [name for name in api.__all__ if getattr(api, name, None) is None]
    assert not missing
    assert api.load_robot("xarm6_leap_hand").name and api.robot_geometry.RobotShapes  # loaded on first use
    with pytest.raises(AttributeError, match="no attribute 'Nothing'"):
        api.Nothing  # noqa: B018


def test_importing_the_api_loads_neither_the_robot_model_nor_the_session_reader():
    code = ("import sys, teleprev.devices; "
            "print(sorted(m for m in ('teleprev.robot.model', 'teleprev.session.reader') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_every_built_in_plugin_is_a_typed_device():
    for name, ep in available().items():
        cls = ep.load()
        assert issubclass(cls, Device) and cls.kind in KINDS, name
        assert dataclasses.is_dataclass(cls.Settings), name
        assert name.split(".")[1] == cls.kind, name
        assert bool(cls.sdk_module) == bool(cls.extra), name


@dataclasses.dataclass
class PingSettings:
    rate_hz: float = 10.0


class Ping(Device[PingSettings], kind="glove"):
    def streams(self) -> list[StreamSpec]:
        return [StreamSpec(self.topic("hand"), "joints", self.settings.rate_hz)]

    def connect(self) -> None:
        pass

    def read(self, timeout_s: float) -> list[Sample]:
        return []


class PingWithSdk(Ping, sdk_module="teleprev_no_such_sdk", extra="ping"):
    pass


def test_settings_come_from_the_type_argument_and_kind_from_the_class_line():
    assert Ping.Settings is PingSettings and Ping.kind == "glove" and not Ping.sdk_module
    assert PingWithSdk.Settings is PingSettings and PingWithSdk.kind == "glove"
    ping = Ping("left", PingSettings(), DeviceContext(SessionClock()))
    assert ping.topic("hand") == "/glove/left/hand" == ping.streams()[0].topic


def test_a_missing_sdk_names_the_extra_to_install():
    assert Ping.sdk_installed() and not PingWithSdk.sdk_installed()
    with pytest.raises(DeviceError, match=r"PingWithSdk: cannot import teleprev_no_such_sdk.*`uv sync --extra ping`"):
        PingWithSdk.import_sdk()
    assert PingWithSdk.import_sdk("json").dumps([1]) == "[1]"
