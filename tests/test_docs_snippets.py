"""The Python blocks of the reference pages other than docs/python-api.md (tests/test_python_api.py)
run as shown, and what they say the calls return is what they return."""

import re

from conftest import ROOT


def block(page: str) -> str:
    return re.search(r"```python\n(.*?)```", (ROOT / "docs" / page).read_text(), re.S).group(1)


def test_the_simulators_python_block_runs():
    code = block("simulator.md")
    scope: dict = {}
    exec(compile(code, "docs/simulator.md", "exec"), scope)
    stated = re.search(r"true_params\(2, \"base\"\)\s+# \{'fc': ([\d.]+), 'fs': ([\d.]+), 'vs': ([\d.]+)", code)
    params = scope["true_params"](2, "base")
    assert [params["fc"], params["fs"], params["vs"]] == [float(x) for x in stated.groups()]
    meta = scope["metadata"](scope["table"])
    assert meta["scenario"] == "extended" and meta["seed"] == 3
    assert [e["name"] for e in meta["effects"]] == ["position", "drift"]
