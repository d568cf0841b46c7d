"""The shares the README and the tutorial give in their prose are those of the output they show
(the console blocks that tools/docs/make_console.py writes)."""

import re

from conftest import ROOT

TUTORIAL = (ROOT / "docs" / "tutorial.md").read_text()
README = (ROOT / "README.md").read_text()


def lower(load: str, rows: str) -> tuple[int, int]:
    """(friction, external torque) share [%] of LuGre's error left by NN_base + NN_add, from the demo's lines."""
    m = re.search(rf"NN_base \+ NN_add vs LuGre, {load} load, {rows} rows: friction (\d+) %, external torque (\d+) %",
                  TUTORIAL)
    return 100 - int(m.group(1)), 100 - int(m.group(2))


def test_the_tutorials_shares_are_the_demos():
    m = re.search(r"In motion the adapted NN_base has (\d+) % \(asymmetric load\) and (\d+) % \(symmetric load\) of "
                  r"the LuGre\s+model's friction error, (\d+) % and (\d+) % of its external-torque error.*?Over all\s+"
                  r"rows, standstill included, it has (\d+) % and (\d+) %", TUTORIAL, re.S)
    assert m, "the tutorial's sentence on the demo's shares"
    asym, sym = lower("asymmetric", "moving"), lower("symmetric", "moving")
    asym_all, sym_all = lower("asymmetric", "all"), lower("symmetric", "all")
    wanted = [asym[0], sym[0], asym[1], sym[1], asym_all[0], sym_all[0]]
    assert [int(s) for s in m.groups()] == wanted     # 100 - the reduction the demo prints


def test_the_readmes_shares_are_its_tables():
    row = re.search(r"\| adapted \| [\d.]+ \(([\d.]+)\) \|", README)
    lugre = re.search(r"\| LuGre \| ([\d.]+) \(([\d.]+)\) \|", README)
    m = re.search(r"In motion the adapted network has (\d+) % of the LuGre model's friction error on the "
                  r"asymmetric-load log;\s+over all rows, standstill included, (\d+) %", README)
    assert row and lugre and m
    adapted_all = float(re.search(r"\| adapted \| ([\d.]+) ", README).group(1))
    assert int(m.group(1)) == round(100 * float(row.group(1)) / float(lugre.group(2)))
    assert int(m.group(2)) == round(100 * adapted_all / float(lugre.group(1)))
