"""The benches' JSON line is strict JSON: a figure a run could not measure is null."""

import importlib.util
import json
from pathlib import Path


def _common():
    spec = importlib.util.spec_from_file_location("bench_common", Path(__file__).parents[1] / "bench" / "common.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_an_unmeasured_figure_is_null_in_the_json_line(capsys):
    _common().report("t", {"measured": 1.5, "unmeasured": float("nan"), "flag": True}, as_json=True)
    line = capsys.readouterr().out.strip().splitlines()[-1]

    def refuse(constant):
        raise ValueError(f"not strict JSON: {constant}")

    assert json.loads(line, parse_constant=refuse) == {"measured": 1.5, "unmeasured": None, "flag": True}
