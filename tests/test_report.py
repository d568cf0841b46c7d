"""Report pages a person reads: every figure has a caption that explains it, every number on
the page and every axis of every figure has its unit, and the page needs nothing but its folder."""

from __future__ import annotations

import html.parser
import re

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import SAMPLE

from fricli.applying import report
from fricli.cli import cli

ASYM = str(SAMPLE / "joint2_extended_asym.parquet")
UNITS = ("Nm", "N", "rad/s", "rad", "m/s", "m", "s", "%", "Hz", "rows", "steps", "samples", "joints", "days")
NUMBER = re.compile(r"(?<![\w.])[-+−]?\d[\d,]*(?:\.\d+)?(?:e[-+]?\d+)?(?![\w.])")
LABELS = ("joint", "Joint", "seed", "Table")   # a number after these names a thing, it measures nothing


class Page(html.parser.HTMLParser):
    """The page's figures (src, caption), table cells with their column heads, other text, links."""

    def __init__(self):
        super().__init__()
        self.figures, self.cells, self.text, self.links = [], [], [], []
        self._stack, self._img, self._head, self._col, self._buf = [], None, [], 0, []

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.links += [attrs[k] for k in ("src", "href") if k in attrs]
        if tag == "img":
            self._img = attrs["src"]
        if tag == "table":
            self._head = []
        if tag == "tr":
            self._col = 0
        self._stack.append(tag)
        self._buf = []

    def handle_endtag(self, tag):
        text = " ".join("".join(self._buf).split())
        self._buf = []
        if tag == "figcaption":
            self.figures.append((self._img, text))
        elif tag == "th":
            self._head.append(text)
        elif tag == "td":
            self.cells.append((self._head[self._col] if self._col < len(self._head) else "", text))
            self._col += 1
        elif tag in ("p", "caption", "h1", "h2", "title", "a") and text:
            self.text.append(text)
        while self._stack and self._stack.pop() != tag:
            pass

    def handle_data(self, data):
        self._buf.append(data)


def unitless(text: str) -> list[str]:
    """The numbers in ``text`` with no unit after them (nor a label such as "joint" before)."""
    bad = []
    for m in NUMBER.finditer(text):
        before, after = text[:m.start()].split(), text[m.end():].strip()
        if before and before[-1].strip("(") in LABELS:
            continue
        after = re.sub(r"^of\s+" + NUMBER.pattern + r"\s*", "", after)   # "3 of 12 rows"
        if not re.match(r"(" + "|".join(map(re.escape, UNITS)) + r")(?![\w/])", after):
            bad.append(f"{m.group()!r} in {text[max(0, m.start() - 40):m.end() + 20]!r}")
    return bad


def check_page(path) -> Page:
    page = Page()
    page.feed(path.read_text())
    assert page.figures, "no figures"
    for src, caption in page.figures:
        assert (path.parent / src).read_bytes()[:4] == b"\x89PNG"
        assert caption and caption != src and src not in caption and len(caption.split()) >= 15, (src, caption)
    assert not [link for link in page.links if re.match(r"[a-z]+:|//", link)], page.links   # offline
    bad = []
    for head, cell in page.cells:
        if NUMBER.fullmatch(cell):
            if not re.search(r"\[[^\]]+\]", head):
                bad.append(f"{cell!r} under {head!r}")
        else:
            bad += unitless(cell)
    for text in page.text + [c for _, c in page.figures]:
        bad += unitless(text)
    assert not bad, bad
    return page


def test_the_unit_check_catches_a_bare_number():
    assert unitless("friction MAE 3.732") and not unitless("friction MAE 3.732 Nm")
    assert not unitless("joint 2: 42.4 % of the rows (6,759 of 15,927 rows)") and unitless("(6,759 of 15,927)")
    assert not unitless("fitted on joint2_base.parquet (Table 2, seed 0)") and unitless("fitted in 2 passes")


@pytest.fixture(scope="module")
def nn_model(tmp_path_factory):
    path = tmp_path_factory.mktemp("m") / "nn.npz"
    res = CliRunner().invoke(cli, ["train-base", str(SAMPLE / "joint2_base.parquet"), "-o", str(path), "--steps", "60",
                                   "-q"])
    assert res.exit_code == 0, res.output
    return str(path)


def test_report_page_captions_and_units(nn_model, tmp_path):
    out = tmp_path / "rep"
    res = CliRunner().invoke(cli, ["report", nn_model, ASYM, "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert re.search(r"friction MAE \d+\.\d+ Nm\)", res.stderr), res.stderr
    page = check_page(out / "index.html")
    assert [src for src, _ in page.figures] == ["loss.png", "friction_velocity.png", "heatmap.png",
                                                "friction_time.png", "quadrants.png", "external_torque.png"]
    assert "Adam step" in dict(page.figures)["loss.png"]


def test_an_interrupted_report_leaves_the_previous_one_whole(nn_model, tmp_path, monkeypatch):
    out = tmp_path / "rep"
    assert CliRunner().invoke(cli, ["report", nn_model, ASYM, "-o", str(out), "-q"]).exit_code == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(report, "fig_quadrants", interrupted)   # after three figures are written
    res = CliRunner().invoke(cli, ["report", nn_model, str(SAMPLE / "joint2_adapt.parquet"), "-o", str(out)])
    assert res.exit_code == 130, res.output
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before     # no file of the new one, no stage


def _axis_units(fig) -> list[str]:
    """Axes of a drawn figure whose numeric tick labels have no unit in the axis label."""
    bad = []
    for ax in fig.axes:
        for axis, label in ((ax.xaxis, ax.get_xlabel()), (ax.yaxis, ax.get_ylabel())):
            ticks = [t.get_text() for t in axis.get_ticklabels() if t.get_visible() and t.get_text()]
            numeric = ticks and all(re.sub(r"mathdefault|[$\\{}^\s.,+\-−]", "", t).isdigit() for t in ticks)
            if numeric and not re.search(r"\[[^\]]+\]", label):
                bad.append(f"{ax.get_title()!r}: {label!r}")
    return bad


def test_every_axis_of_every_figure_has_a_unit(nn_model, tmp_path, monkeypatch):
    seen = []
    original = report.save

    def keep(fig, folder, name, caption):
        shown = original(fig, folder, name, caption)   # draws the figure: tick labels are set
        seen.append((name, _axis_units(fig)))
        return shown

    monkeypatch.setattr(report, "save", keep)
    res = CliRunner().invoke(cli, ["report", nn_model, ASYM, "-o", str(tmp_path / "rep"), "-q"])
    assert res.exit_code == 0, res.output
    assert len(seen) == 6 and all(not bad for _, bad in seen), seen


def check_demo_page(folder) -> None:
    """The demo's page (tests/test_evaluate.py runs the demo): the comparison table, with the
    numbers of table.md, and the fits before the model's own figures."""
    page = check_page(folder / "report" / "index.html")
    files = [src for src, _ in page.figures]
    assert files[:2] == ["comparison.png", "fits_velocity.png"] and "loss.png" in files
    assert "asymmetric load: friction MAE [Nm]" in {head for head, _ in page.cells}
    table_md = (folder / "table.md").read_text()
    rows = [line.split("|")[1:-1] for line in table_md.splitlines() if line.startswith("| LuGre |")]
    cells = [c for h, c in page.cells if h != "method"]
    assert rows and [c.strip() for c in rows[0][1:]] == cells[:6]     # the same numbers as table.md


def test_trend_figure_has_units(tmp_path, rng, monkeypatch):
    import test_fleet
    from matplotlib.figure import Figure

    from fricli.fleet import history, trend

    drawn = []
    original = Figure.savefig

    def keep(self, *args, **kwargs):
        original(self, *args, **kwargs)
        drawn.append(self)

    monkeypatch.setattr(Figure, "savefig", keep)
    test_fleet.synthetic_history(tmp_path / "h", rng)
    result = trend.trends(history.read(str(tmp_path / "h")))
    paths = trend.figures(result, trend.WearRule(), str(tmp_path / "fig"))
    assert len(paths) == len(drawn) == 1
    ax = drawn[0].axes[0]
    assert "[-]" in ax.get_ylabel() and "[day]" in ax.get_xlabel()
    assert all("(baseline" in t.get_text() for t in ax.get_legend().get_texts()[:2])
    assert np.isfinite(ax.get_ylim()).all()


def test_every_report_figure_names_its_joint_and_log(nn_model, tmp_path, monkeypatch):
    """A PNG copied out of the report page still says what it shows."""
    titles = []
    original = report.save

    def keep(fig, folder, name, caption):
        titles.append((name, fig._suptitle.get_text() if fig._suptitle else ""))
        return original(fig, folder, name, caption)

    monkeypatch.setattr(report, "save", keep)
    res = CliRunner().invoke(cli, ["report", nn_model, ASYM, "-o", str(tmp_path / "rep"), "-q"])
    assert res.exit_code == 0, res.output
    log = ASYM.split("/")[-1]
    assert len(titles) == 6 and all(t == f"joint 2 of {log}, model nn.npz" for _, t in titles), titles
