"""--webxr-host mistakes get one line before anything opens."""

from tests.helpers.cli import teleprev


def test_a_webxr_host_that_is_no_address_or_a_rig_without_a_page_is_one_line(tmp_path):
    bad = teleprev("record", "rigs/webxr_sim.toml", "--webxr-host", "my-laptop", "--duration", "1", "--no-preview",
                   "--out", str(tmp_path / "a.mcap"))
    assert bad.returncode == 2
    assert "--webxr-host: host must be an IPv4 address to listen on (e.g. 127.0.0.1), got 'my-laptop'" in bad.stderr
    none = teleprev("devices", "check", "rigs/sim.toml", "--webxr-host", "0.0.0.0")
    assert none.returncode == 2 and "--webxr-host: the rig has no webxr.* device" in none.stderr
    assert not (tmp_path / "a.mcap").exists()


def test_a_webxr_host_the_rig_already_has_is_taken_as_it_is():
    """Naming the address the rig file already gives is no mistake (it was refused as "no webxr device")."""
    from pathlib import Path

    from teleprev.rig import load_rig

    rig = load_rig(Path(__file__).parents[2] / "rigs" / "webxr_sim.toml")
    same = rig.with_device_settings("webxr", "--webxr-host", host="127.0.0.1")
    assert {n: d.settings.host for n, d in same.devices.items() if d.plugin.startswith("webxr.")} == {
        "glove": "127.0.0.1", "suit": "127.0.0.1"}
    wide = rig.with_device_settings("webxr", "--webxr-host", host="0.0.0.0")
    assert wide.devices["glove"].settings.host == wide.devices["suit"].settings.host == "0.0.0.0"
