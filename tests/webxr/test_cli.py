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
