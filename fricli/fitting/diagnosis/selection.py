"""Held-out scores, significance and forward selection of candidate effects.

The log is cut into K contiguous folds over time (blocked cross-validation: a fold is
predicted by a fit on the other K-1 folds, so slow trends and autocorrelated noise cannot
leak from neighbouring rows). Each fold is cut again into short contiguous blocks; for any set
of regressor columns the held-out sum of squared residuals per block comes from per-block
Gram matrices of the standardised columns and the residual, so scoring a candidate costs K
small solves, not a pass over the data.

Significance compares two fits' held-out squared errors block by block (a Diebold-Mariano
test with the variance from block means, so autocorrelation inside a block does not inflate
it): the richer fit is *significant* when its mean improvement per block is positive in a
one-sided t-test at level ``alpha``. A candidate is *chosen* when it is significant, removes at
least ``min_gain`` of the remaining held-out squared residual, beats its declared rivals
(combinations of simpler effects it overlaps) by the same two criteria, and no candidate with
fewer new terms does nearly as well (the richer one must beat it by the same criteria too).
"""

from __future__ import annotations

import dataclasses

import numpy as np

RIDGE = 1e-10            # relative to n: keeps exactly collinear sets solvable, far below any signal
BLOCKS_PER_FOLD = 10     # blocks per fold for the significance test
MIN_BLOCK_ROWS = 20


def fold_bounds(n: int, k: int) -> np.ndarray:
    """Start/stop indices (k+1,) of k contiguous blocks of nearly equal size."""
    return np.linspace(0, n, k + 1).round().astype(int)


def block_bounds(n: int, folds: int) -> tuple[np.ndarray, np.ndarray]:
    """(block bounds (B+1,), fold of each block (B,)): each fold cut into contiguous blocks."""
    per = max(1, min(BLOCKS_PER_FOLD, n // (folds * MIN_BLOCK_ROWS)))
    edges = fold_bounds(n, folds)
    bounds, fold = [0], []
    for f, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        inner = np.linspace(a, b, per + 1).round().astype(int)[1:]
        bounds.extend(int(x) for x in inner)
        fold.extend([f] * per)
    return np.array(bounds), np.array(fold)


class Design:
    """Named regressor columns over a log, with per-block Gram matrices for held-out scores.

    columns are added by term name; ``sse(names)`` gives the held-out sum of squared residuals
    per block (B,) for the least-squares fit of the residual on those columns, each block
    predicted by the fit on the folds it is not part of.
    """

    def __init__(self, residual: np.ndarray, folds: int):
        self.r = np.asarray(residual, dtype=np.float64)
        self.folds = folds
        self.bounds, self.fold_of = block_bounds(len(self.r), folds)
        self.k = len(self.bounds) - 1
        self.names: list[str] = []
        self.cols: list[np.ndarray] = []
        self.scale: list[float] = []
        self._gram = None
        self._cache: dict[frozenset, np.ndarray] = {}
        self.rscale = float(np.sqrt(np.mean(self.r ** 2))) or 1.0

    def has(self, name: str) -> bool:
        return name in self.names

    def add(self, name: str, column: np.ndarray) -> None:
        if name in self.names:
            return
        column = np.asarray(column, dtype=np.float64)
        rms = float(np.sqrt(np.mean(column ** 2)))
        self.names.append(name)
        self.cols.append(column)
        self.scale.append(rms)

    def live(self, names) -> list[int]:
        """Column indices of ``names`` that are not identically zero."""
        idx = [self.names.index(n) for n in names]
        return [i for i in idx if self.scale[i] > 0]

    def _z(self, a: int, b: int) -> np.ndarray:
        m = len(self.cols)
        z = np.empty((b - a, m + 1))
        for j, (c, s) in enumerate(zip(self.cols, self.scale)):
            z[:, j] = c[a:b] / s if s > 0 else 0.0
        z[:, m] = self.r[a:b] / self.rscale
        return z

    def gram(self) -> np.ndarray:
        """Per-block Gram matrices (B, m+1, m+1) of the standardised columns and, last, the
        residual; columns added since the last call only add their own rows and columns."""
        m = len(self.cols)
        old = self._gram
        if old is not None and old.shape[1] == m + 1:
            return old
        m0 = 0 if old is None else old.shape[1] - 1
        G = np.empty((self.k, m + 1, m + 1))
        if m0:
            G[:, :m0, :m0] = old[:, :m0, :m0]
            G[:, :m0, m] = old[:, :m0, m0]
            G[:, m, :m0] = old[:, m0, :m0]
            G[:, m, m] = old[:, m0, m0]
        for i, (a, b) in enumerate(zip(self.bounds[:-1], self.bounds[1:])):
            z = self._z(a, b)
            if m0:
                cross = z[:, m0:m].T @ z
                G[i, m0:m, :] = cross
                G[i, :, m0:m] = cross.T
            else:
                G[i] = z.T @ z
        self._gram = G
        return G

    def _solve(self, A: np.ndarray, b: np.ndarray, n_train: int) -> np.ndarray:
        A = A + RIDGE * max(n_train, 1) * np.eye(len(A))
        try:
            return np.linalg.solve(A, b)
        except np.linalg.LinAlgError:
            return np.linalg.lstsq(A, b, rcond=None)[0]

    def _fold_betas(self, idx: list[int]) -> list[np.ndarray]:
        """Coefficients (standardised) fitted without each fold, one per fold."""
        G = self.gram()
        m = G.shape[1] - 1
        total = G.sum(axis=0)
        sizes = np.diff(self.bounds)
        out = []
        for f in range(self.folds):
            mine = self.fold_of == f
            Gf = G[mine].sum(axis=0)
            A = total[np.ix_(idx, idx)] - Gf[np.ix_(idx, idx)]
            b = total[idx, m] - Gf[idx, m]
            out.append(self._solve(A, b, int(sizes[~mine].sum())))
        return out

    def sse(self, names) -> np.ndarray:
        """Held-out SSE per block (B,), in units of the residual's mean square."""
        idx = self.live(names)
        key = frozenset(idx)
        if key in self._cache:
            return self._cache[key]
        G = self.gram()
        m = G.shape[1] - 1
        out = G[:, m, m].copy()
        if idx:
            Gi = G[:, idx][:, :, idx]
            gi = G[:, idx, m]
            for f, beta in enumerate(self._fold_betas(idx)):
                mine = self.fold_of == f
                out[mine] += -2.0 * gi[mine] @ beta + np.einsum("bij,i,j->b", Gi[mine], beta, beta)
            out = np.maximum(out, 0.0)
        self._cache[key] = out
        return out

    def heldout_prediction(self, names) -> np.ndarray:
        """The residual predicted on each fold by a fit on the other folds (n,)."""
        idx = self.live(names)
        pred = np.zeros_like(self.r)
        if not idx:
            return pred
        edges = fold_bounds(len(self.r), self.folds)
        for f, beta in enumerate(self._fold_betas(idx)):
            a, b = edges[f], edges[f + 1]
            X = np.column_stack([self.cols[i][a:b] / self.scale[i] for i in idx])
            pred[a:b] = X @ beta * self.rscale
        return pred

    def fit(self, names) -> dict[str, float]:
        """Coefficients of the least-squares fit on all rows, by name (zero for dead columns)."""
        idx = self.live(names)
        out = {n: 0.0 for n in names}
        if not idx:
            return out
        X = np.column_stack([self.cols[i] / self.scale[i] for i in idx])
        beta, *_ = np.linalg.lstsq(X, self.r, rcond=1e-10)
        for i, b in zip(idx, beta):
            out[self.names[i]] = float(b / self.scale[i])
        return out

    def fitted(self, names) -> np.ndarray:
        """The full-data fit's prediction of the residual (n,)."""
        coef = self.fit(names)
        out = np.zeros_like(self.r)
        for n, b in coef.items():
            if b:
                out += b * self.cols[self.names.index(n)]
        return out


@dataclasses.dataclass
class Comparison:
    """Held-out comparison of a richer fit (new) against a reference fit (old)."""

    gain: float            # 1 - sum(sse_new) / sum(sse_old): share of the old held-out SSE removed
    t: float               # t statistic of the per-block improvements
    significant: bool

    def clear(self, min_gain: float) -> bool:
        return self.significant and self.gain >= min_gain


def compare(sse_new: np.ndarray, sse_old: np.ndarray, alpha: float) -> Comparison:
    """Is the fit with held-out block SSEs ``sse_new`` (B,) better than ``sse_old`` (B,)?"""
    old = float(sse_old.sum())
    if old <= 0:
        return Comparison(0.0, 0.0, False)
    d = sse_old - sse_new
    gain = float(d.sum()) / old
    k = len(d)
    sd = float(np.std(d, ddof=1)) if k > 1 else 0.0
    mean = float(d.mean())
    if sd > 0:
        t = mean / (sd / np.sqrt(k))
    else:
        t = float("inf") if mean > 0 else 0.0
    from scipy import special  # the t quantile of scipy.stats.t.ppf, without importing scipy.stats (a quarter second)

    crit = float(special.stdtrit(max(k - 1, 1), 1.0 - alpha))
    return Comparison(gain, float(t), bool(gain > 0 and t >= crit))


@dataclasses.dataclass
class Candidate:
    """One effect's terms at a selection step."""

    name: str
    terms: list[str]                                  # term names
    rivals: tuple[tuple[str, ...], ...] = ()


@dataclasses.dataclass
class Score:
    name: str
    gain: float             # share of the original held-out SSE this candidate removes (marginal)
    step_gain: float        # share of the current held-out SSE it removes
    t: float
    significant: bool       # significant against the current fit and against its rivals
    eligible: bool
    n_new: int
    terms: list[str] = dataclasses.field(default_factory=list)


@dataclasses.dataclass
class Selection:
    added: list[str]
    steps: list[Score]                       # the chosen candidate's score at each step
    final: dict[str, Score]                  # every candidate not added, scored against the final set
    first: dict[str, Score]                  # every candidate scored alone on the model's residual
    terms: list[str]                         # term names of the chosen effects, in order
    sse0: float
    sse_final: float


def score(design: Design, cand: Candidate, base_terms: list[str], sse_base: np.ndarray, sse0: float,
          term_of: dict[str, list[str]], alpha: float, min_gain: float) -> Score:
    names = _union(base_terms, cand.terms)
    sse_new = design.sse(names)
    cmp = compare(sse_new, sse_base, alpha)
    ok_sig, ok_clear = cmp.significant, cmp.clear(min_gain)
    for combo in cand.rivals:
        rival = base_terms
        for r in combo:
            rival = _union(rival, term_of.get(r, []))
        if set(rival) >= set(names):
            continue
        rc = compare(sse_new, design.sse(rival), alpha)
        ok_sig = ok_sig and rc.significant
        ok_clear = ok_clear and rc.clear(min_gain)
    gain_total = (float(sse_base.sum()) - float(sse_new.sum())) / sse0 if sse0 > 0 else 0.0
    n_new = len(set(design.live(names)) - set(design.live(base_terms)))
    return Score(cand.name, gain_total, cmp.gain, cmp.t, ok_sig, ok_sig and ok_clear and n_new > 0, n_new,
                 list(cand.terms))


def _union(a: list[str], b: list[str]) -> list[str]:
    return list(a) + [x for x in b if x not in a]


def forward(design: Design, candidates, *, alpha: float = 0.01, min_gain: float = 0.1,
            max_effects: int | None = None, twins: tuple[tuple[str, str], ...] = ()) -> Selection:
    """Forward selection with backward pruning. ``candidates(chosen_terms, residual)`` returns
    the list of ``Candidate`` for the current step (terms already added to ``design``).

    When no candidate qualifies any more, an effect added earlier that the others now make
    unnecessary (the full set does not beat the set without it by the same criteria, e.g. a
    trend in time taken before the temperature that explains it) is dropped and may not return;
    the forward steps then go on. Last, an effect whose twin (``twins``: pairs of effects that
    explain much the same, e.g. a gravity-model error and quadrant friction) is not chosen
    is replaced by it when that leaves less held-out error, and the steps go on again."""
    chosen: list[str] = []
    steps: list[Score] = []
    first: dict[str, Score] = {}
    dropped: set[str] = set()
    added: dict[str, list[str]] = {}        # the chosen effects' terms as they were chosen
    rivals_of: dict[str, tuple] = {}
    sse0 = float(design.sse([]).sum())
    while True:
        chosen_terms = _terms_of(chosen, added)
        residual = design.r - design.fitted(chosen_terms)
        cands = candidates(chosen_terms, residual)
        term_of = {c.name: c.terms for c in cands}
        term_of.update(added)
        rivals_of.update({c.name: c.rivals for c in cands})
        sse_base = design.sse(chosen_terms)
        scores = {c.name: score(design, c, chosen_terms, sse_base, sse0, term_of, alpha, min_gain)
                  for c in cands if c.name not in chosen}
        if not first:
            first = dict(scores)
        limit = max_effects is not None and len(chosen) >= max_effects
        eligible = sorted((s for s in scores.values() if s.eligible and s.name not in dropped), key=lambda s: -s.gain)
        if eligible and not limit:
            best = eligible[0]
            for other in eligible[1:]:
                if other.n_new < best.n_new and not _beats(design, term_of[best.name], term_of[other.name],
                                                           chosen_terms, alpha, min_gain):
                    best = other
            chosen.append(best.name)
            added[best.name] = term_of[best.name]
            steps.append(best)
            continue
        spare = _spare(design, chosen, added, alpha, min_gain)
        if spare is not None:
            dropped.add(spare)
            chosen.remove(spare)
            del added[spare]
        else:
            swap = _better_twin(design, chosen, added, term_of, twins, dropped)
            if swap is None:
                break
            old, new = swap
            dropped.add(old)
            chosen[chosen.index(old)] = new
            del added[old]
            added[new] = term_of[new]
        steps = _rescore(design, chosen, added, rivals_of, sse0, alpha, min_gain)
    return Selection(chosen, steps, scores, first, chosen_terms, sse0, float(sse_base.sum()))


def _terms_of(names: list[str], term_of: dict[str, list[str]]) -> list[str]:
    out: list[str] = []
    for name in names:
        out = _union(out, term_of[name])
    return out


def _better_twin(design: Design, chosen: list[str], added, term_of, twins, dropped) -> tuple[str, str] | None:
    """(chosen effect, its twin) when the twin in its place leaves less held-out error, else None."""
    full = _terms_of(chosen, added)
    for pair in twins:
        for a, b in (pair, pair[::-1]):
            if a in chosen and b not in chosen and b not in dropped and b in term_of:
                swapped = _union(_terms_of([c for c in chosen if c != a], added), term_of[b])
                if design.sse(swapped).sum() < design.sse(full).sum():
                    return a, b
    return None


def _spare(design: Design, chosen: list[str], term_of, alpha: float, min_gain: float) -> str | None:
    """The earliest chosen effect the others make unnecessary, or None."""
    full = _terms_of(chosen, term_of)
    for name in chosen:
        rest = _terms_of([c for c in chosen if c != name], term_of)
        if set(rest) >= set(full):
            continue
        if not compare(design.sse(full), design.sse(rest), alpha).clear(min_gain):
            return name
    return None


def _rescore(design: Design, chosen: list[str], term_of, rivals_of, sse0: float, alpha: float,
             min_gain: float) -> list[Score]:
    """Scores of the chosen effects, reordered greedily: each the one that removes the most of
    what the ones before it leave (``chosen`` is reordered in place to match)."""
    out, base, left = [], [], list(chosen)
    while left:
        sse_base = design.sse(base)
        scores = [score(design, Candidate(n, term_of[n], rivals_of.get(n, ())), base, sse_base, sse0, term_of,
                        alpha, min_gain) for n in left]
        best = max(scores, key=lambda sc: sc.gain)
        out.append(best)
        left.remove(best.name)
        base = _union(base, term_of[best.name])
    chosen[:] = [sc.name for sc in out]
    return out


def _beats(design: Design, richer: list[str], simpler: list[str], base: list[str], alpha: float,
           min_gain: float) -> bool:
    a, b = _union(base, richer), _union(base, simpler)
    return compare(design.sse(a), design.sse(b), alpha).clear(min_gain)
