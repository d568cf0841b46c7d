"""The measured figures of the sample data in docs/simulator.md, written from the files.

    python tools/docs/make_sample_figures.py docs/simulator.md      # rewrites the marked section

Reads every log of sample_data/, identifies the LuGre model on joint 2's and joint 4's base log
(as ``fricli identify`` does) and scores it and the simulator's true base-state model.
"""

from __future__ import annotations

import os
import re
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT)

import numpy as np  # noqa: E402

from fricli.core import logs, metrics  # noqa: E402
from fricli.fitting.identify import identify  # noqa: E402
from fricli.models.lugre import LuGreModel  # noqa: E402
from fricli.sim.simulator import true_params  # noqa: E402

SAMPLE = os.path.join(ROOT, "sample_data")
KINDS = ("base", "extended_none", "extended_sym", "extended_asym", "adapt")
BEGIN = "<!-- sample figures: written by tools/docs/make_sample_figures.py -->"
END = "<!-- end of sample figures -->"


def _range(x: np.ndarray) -> str:
    lo, hi = float(np.min(x)), float(np.max(x))
    return "0" if lo == hi == 0 else f"{lo:.1f} .. {hi:.1f}".replace("-", "−")


def _mae(model, log) -> float:
    return metrics.errors(logs.friction_target(log.signals), model.predict(log.signals)[0])["mae"]


def section() -> str:
    rows, total = [], 0
    for joint in (2, 4):
        for kind in KINDS:
            path = os.path.join(SAMPLE, f"joint{joint}_{kind}.parquet")
            sig = logs.load_log(path).signals
            noise = logs.friction_target(sig) - sig["tau_f_true"]
            size = os.path.getsize(path)
            total += size
            rows.append(f"| `joint{joint}_{kind}.parquet` | {len(sig['t'])} | {sig['t'][-1] - sig['t'][0]:.1f} | "
                        f"{_range(sig['tau_g'])} | {_range(sig.get('tau_ext', np.zeros(1)))} | "
                        f"{np.max(np.abs(sig['qd'])):.2f} | {np.mean(np.abs(noise)):.3f} | {np.std(noise):.3f} | "
                        f"{size / 1000:.0f} kB |")
    lines = [BEGIN, "",
             "| file | rows | s | tau_g [Nm] | tau_ext [Nm] | max \\|qd\\| | noise MAE [Nm] | noise sd [Nm] | size |",
             "|---|---|---|---|---|---|---|---|---|", *rows, "",
             f"(noise = friction target − `tau_f_true`; {total / 1e6:.2f} MB in total.)", ""]
    true_mae, ratio, fitted = {}, {}, {}
    for joint in (2, 4):
        base = logs.load_log(os.path.join(SAMPLE, f"joint{joint}_base.parquet"))
        params = {k: v for k, v in true_params(joint).items() if k in LuGreModel.__init__.__code__.co_varnames}
        true_mae[joint] = _mae(LuGreModel(**params), base)
        ratio[joint] = true_mae[joint] / np.mean(np.abs(logs.friction_target(base.signals) - base.signals["tau_f_true"]))
        fitted[joint] = identify(base).model_
    p = fitted[2]
    scored = {j: [_mae(fitted[j], logs.load_log(os.path.join(SAMPLE, f"joint{j}_extended_{load}.parquet")))
                  for load in ("none", "sym", "asym")] for j in (2, 4)}
    base2 = logs.load_log(os.path.join(SAMPLE, "joint2_base.parquet"))
    lines += [
        f"- The true base-state LuGre model, evaluated at 100 Hz on the base logs, has a friction MAE of "
        f"{true_mae[2]:.3f} Nm (joint 2) and {true_mae[4]:.3f} Nm (joint 4) against the target: "
        f"{ratio[2]:.2f} and {ratio[4]:.2f} x the noise MAE.",
        f"- `fricli identify` on `joint2_base.parquet` gives `fc` {p.fc:.4g}, `fs` {p.fs:.4g}, `vs` {p.vs:.3g}, "
        f"`delta` {p.delta:.4g}, `fv` {p.fv:.4g}, `kc` {p.kc:.3g}, `ks` {p.ks:.3g} (MAE {_mae(p, base2):.3f} Nm); that "
        f"model has a friction MAE of {' / '.join(f'{v:.2f}' for v in scored[2])} Nm on "
        f"`joint2_extended_{{none,sym,asym}}`, and joint 4's model {' / '.join(f'{v:.2f}' for v in scored[4])} Nm "
        "on joint 4's.",
        "", END]
    return "\n".join(lines)


def main(argv: list[str]) -> None:
    text = section()
    for path in argv or []:
        with open(path, encoding="utf-8") as fh:
            doc = fh.read()
        new = re.sub(re.escape(BEGIN) + ".*?" + re.escape(END), lambda _: text, doc, flags=re.S)
        if new == doc and BEGIN not in doc:
            raise SystemExit(f"{path}: no section marked {BEGIN}")
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(new)
        print(f"wrote {path}")
    if not argv:
        print(text)


if __name__ == "__main__":
    main(sys.argv[1:])
