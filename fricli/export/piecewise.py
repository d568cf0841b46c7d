"""C code of polynomial pieces (``fricli.numerics.piecewise``): the tables, and a function that
finds the piece of an input by bisection of the edges and evaluates it by Horner's rule."""

from __future__ import annotations

from fricli.export.c import array, num
from fricli.numerics.piecewise import WIDTH, Pieces


def c_function(name: str) -> str:
    """C definition of ``double <name>(const double *edges, const double *table, int n, double u)``:
    the piece of the n whose edges hold u (edges[0..n]), by Horner's rule."""
    horner = f"p[{WIDTH - 1}]"
    for i in range(WIDTH - 2, 1, -1):
        horner = f"{horner} * t + p[{i}]" if i == WIDTH - 2 else f"({horner}) * t + p[{i}]"
    return "\n".join([
        f"static inline double {name}(const double *edges, const double *table, int n, double u) {{",
        "    int lo = 0, hi = n;",
        "    const double *p;",
        "    double t;",
        "    while (hi - lo > 1) { const int mid = (lo + hi) / 2; if (u < edges[mid]) hi = mid; else lo = mid; }",
        f"    p = table + lo * {WIDTH};",
        "    t = (u - p[0]) * p[1];",
        f"    return {horner};",
        "}", ""])


def c_tables(name: str, pieces: Pieces) -> str:
    """The file-scope tables ``<name>_edges`` and ``<name>`` (WIDTH numbers a piece) of ``pieces``."""
    n = len(pieces.table)
    return "\n".join([f"static const double {name}_edges[{n + 1}] = {array(pieces.edges, 4)};",
                      f"static const double {name}[{n * WIDTH}] = {array(pieces.table, 4)};"])


def c_call(function: str, name: str, pieces: Pieces, u: str) -> str:
    """The C expression of ``pieces`` at ``u``, through ``c_function``'s function and ``c_tables``' tables."""
    if len(pieces.table) == 1 and pieces.table[0, 1] == 0.0:
        return num(pieces.table[0, 2])
    return f"{function}({name}_edges, {name}, {len(pieces.table)}, {u})"
