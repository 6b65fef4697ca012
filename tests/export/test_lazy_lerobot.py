"""lerobot (~15 s to import) and torch (~5 s) load only when a dataset is written or read: the export
modules that hold settings and plan an export, `teleprev --help` and `teleprev info` import neither.
Each check runs in a fresh interpreter, since this one has imported them already."""

import json
import subprocess
import sys

import pytest

HEAVY = ("lerobot", "torch")


def heavy_modules_after(code: str) -> list[str]:
    script = (f"import json, sys\n{code}\n"
              f"print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in {HEAVY!r})))")
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout.splitlines()[-1])


def run_cli(*args: str) -> str:
    return (f"sys.argv = ['teleprev', *{list(args)!r}]\n"
            "from teleprev.cli.app import main\n"
            "try:\n    main()\nexcept SystemExit as exc:\n    assert not exc.code, f'exit {exc.code}'")


@pytest.mark.parametrize("module", ["teleprev.export.video", "teleprev.export.dataset", "teleprev.export.run",
                                    "teleprev.export.parallel", "teleprev.cli.app"])
def test_importing_does_not_load_lerobot_or_torch(module):
    assert heavy_modules_after(f"import {module}") == []


@pytest.mark.parametrize("args", [("--help",), ("export", "--help")])
def test_help_does_not_load_lerobot_or_torch(args):
    assert heavy_modules_after(run_cli(*args)) == []


def test_info_on_a_session_does_not_load_lerobot_or_torch(tmp_path):
    from teleprev.export.synthetic import EpisodeSpec, SyntheticSession, write_session

    path = write_session(tmp_path / "s.mcap", SyntheticSession((EpisodeSpec("pour", 0.5),), seed=1))
    assert heavy_modules_after(run_cli("info", str(path))) == []


def test_the_check_sees_lerobot_where_it_is_imported():
    assert "lerobot" in heavy_modules_after("import teleprev.export.lerobot_video")
