"""The device plugin API: everything a plugin author needs, importable from this one module.

    from teleprev.devices import Device, DeviceContext, StreamSpec, JointSample, DeviceError

See the README's "Writing a device plugin" for a complete plugin, its entry point and its test.
"""

from teleprev.devices.contract import KINDS, Actuator, Device, DeviceContext, NoSettings, StreamSpec
from teleprev.devices.registry import available, load_plugin
from teleprev.devices.runner import ActuatorPort, DeviceRunner, RunnerStats
