"""Which rows of a log a network trains and validates on.

Velocity balance. A base log holds constant-velocity sweeps, each level once per direction;
slow levels take longer and so hold far more samples, and a loss over all rows would favour
them. ``velocity_groups`` finds the velocity levels: it histograms the signed velocity on a
fine logarithmic grid (150 bins per direction between 1e-3 and 1 times the top speed, plus a
bin for |qd| below that) and calls the velocities discrete when the dense bins (each with at
least 0.2 % of the rows) hold at least 75 % of the rows and form narrow runs (at most four
adjacent bins, about +-10 % in speed; wider runs are a continuum of velocities). A level is
such a run, and rows in no level (accelerations between levels) are left out. Otherwise the
velocities are continuous and the groups are 32 equal-width bins of signed velocity.
``balanced`` then draws the same number of rows from every group (all rows of a group that
holds fewer).

Continuous excitation. A log without velocity levels (a real arm running sums of harmonics)
has no steady state to balance: ``select`` then takes the moving rows it is given, as they
come (mode "moving"), at most ``max_samples`` of them drawn at random.

Validation by segments. Neighbouring rows are nearly identical, so a random-row validation
set would only measure interpolation between training rows. ``split_segments`` cuts every run
of consecutive rows in one velocity group (for continuous velocities: the whole log) into ten
contiguous pieces and holds out round(10 * val_fraction) pieces of each, chosen at random, so
every level keeps training rows and the validation rows come in whole stretches of motion.
In mode "moving" the validation rows are whole blocks of time instead (``time_blocks``): the
log cut into ten blocks of equal duration, round(10 * val_fraction) of them held out, so the
validation rows follow other harmonics' phases than the training rows, not the neighbours of
training rows. ``time_folds`` groups the ten blocks into folds for cross-validation (five folds
of two blocks for a validation fraction of 0.2).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fricli.core.errors import DataError

FINE_BINS = 150          # per direction, logarithmic
LOW = 1e-3               # lowest binned speed, relative to the top speed
DENSE = 0.002            # a dense bin holds at least this share of the rows
DISCRETE_SHARE = 0.75    # dense bins must hold this share of the rows
MAX_LEVEL_BINS = 4       # a level spans at most this many adjacent fine bins (about +-10 % in speed) ...
WIDE_SHARE = 0.1         # ... except for this share of the rows in levels
CONTINUOUS_BINS = 32
PIECES = 10              # validation pieces per run
MIN_RUN = 20             # shorter runs (rows) all go to training
PLATEAU_SHARE = 0.5      # steady rows (identify's rule) in this share of the rows in motion: a log of plateaus


@dataclasses.dataclass
class Selection:
    """Rows (sorted indices into the log) for training and validation."""

    train: np.ndarray
    val: np.ndarray
    blocks: np.ndarray  # (n,) int: the piece (levels, all) or time block (moving) of every row, -1 for rows not used
    mode: str          # "levels" (discrete velocities), "moving" (continuous: the moving rows) or "all" (no balancing)
    groups: int        # velocity levels found ("levels"), time blocks held out ("moving")

    def summary(self) -> dict:
        return {"train_rows": int(self.train.size), "val_rows": int(self.val.size),
                "velocity_groups": self.mode, "groups": int(self.groups)}


def velocity_groups(qd: np.ndarray) -> tuple[np.ndarray, str]:
    """(labels (n,) int, mode): a velocity level or bin per row, -1 for rows in none.

    mode is "levels" when the velocities are discrete, else "bins".
    """
    qd = np.asarray(qd, dtype=np.float64)
    n = qd.size
    vmax = float(np.max(np.abs(qd))) if n else 0.0
    if not vmax > 0:
        raise DataError("the log holds no motion (qd is zero everywhere)")
    speed = np.abs(qd)
    lo = LOW * vmax
    pos = np.zeros(n, dtype=np.int64)  # 0: below lo; 1..FINE_BINS: log bins
    moving = speed >= lo
    rel = np.log(speed[moving] / lo) / np.log(1.0 / LOW)
    pos[moving] = 1 + np.minimum((rel * FINE_BINS).astype(np.int64), FINE_BINS - 1)
    fine = np.where(qd < 0, -pos, pos) + FINE_BINS          # 0 .. 2 FINE_BINS, FINE_BINS = rest
    counts = np.bincount(fine, minlength=2 * FINE_BINS + 1)
    dense = counts >= max(DENSE * n, 5)
    if counts[dense].sum() >= DISCRETE_SHARE * n:
        level_of_bin = np.full(counts.size, -1, dtype=np.int64)
        level, prev = -1, False
        for b in range(counts.size):
            # adjacent dense bins form one level, except across the rest bin
            if dense[b]:
                if not prev or b == FINE_BINS or b == FINE_BINS + 1:
                    level += 1
                level_of_bin[b] = level
            prev = bool(dense[b])
        # levels are narrow: a wide run of dense bins is a continuum of velocities
        width = np.bincount(level_of_bin[dense], minlength=level + 1)
        rows = np.bincount(level_of_bin[dense], weights=counts[dense], minlength=level + 1)
        if rows[width > MAX_LEVEL_BINS].sum() <= WIDE_SHARE * rows.sum():
            return level_of_bin[fine], "levels"
    edges = np.linspace(-vmax, vmax, CONTINUOUS_BINS + 1)
    labels = np.clip(np.searchsorted(edges, qd, side="right") - 1, 0, CONTINUOUS_BINS - 1)
    return labels.astype(np.int64), "bins"


def runs(labels: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of every maximal run of equal labels, labels >= 0 only."""
    if labels.size == 0:
        return []
    change = np.flatnonzero(np.diff(labels)) + 1
    starts = np.concatenate(([0], change))
    stops = np.concatenate((change, [labels.size]))
    return [(int(a), int(b)) for a, b in zip(starts, stops) if labels[a] >= 0]


def split_segments(labels: np.ndarray, val_fraction: float, rng: np.random.Generator) -> np.ndarray:
    """Boolean mask (n,) of validation rows: whole contiguous pieces of every run of equal
    labels >= 0 (see the module doc)."""
    n = labels.size
    val = np.zeros(n, dtype=bool)
    held = int(round(PIECES * val_fraction))
    if held <= 0:
        return val
    held = min(held, PIECES - 1)
    for start, stop in runs(labels):
        if stop - start < MIN_RUN:
            continue
        cuts = np.linspace(start, stop, PIECES + 1).astype(np.int64)
        for piece in rng.choice(PIECES, size=held, replace=False):
            val[cuts[piece]:cuts[piece + 1]] = True
    return val


def pieces(labels: np.ndarray) -> np.ndarray:
    """(n,) int: the piece 0..PIECES-1 of every row in a run of equal labels >= 0 (runs cut as
    by ``split_segments``), -1 for rows in no run or in a run shorter than MIN_RUN."""
    out = np.full(labels.size, -1, dtype=np.int64)
    for start, stop in runs(labels):
        if stop - start >= MIN_RUN:
            cuts = np.linspace(start, stop, PIECES + 1).astype(np.int64)
            out[start:stop] = np.searchsorted(cuts, np.arange(start, stop), side="right") - 1
    return out


def held_blocks(val_fraction: float) -> int:
    """Time blocks (of PIECES) held out for ``val_fraction``: at least one when it is above 0,
    and one left for training."""
    return min(max(int(round(PIECES * val_fraction)), 1 if val_fraction > 0 else 0), PIECES - 1)


def time_block(n: int) -> np.ndarray:
    """(n,) int: the block 0..PIECES-1 of every row, the rows cut into PIECES contiguous blocks."""
    cuts = np.linspace(0, n, PIECES + 1).astype(np.int64)
    return np.searchsorted(cuts, np.arange(n), side="right") - 1


def time_blocks(n: int, val_fraction: float, rng: np.random.Generator) -> np.ndarray:
    """Boolean mask (n,) of validation rows: ``held_blocks(val_fraction)`` of the PIECES
    contiguous blocks of ``time_block``, drawn at random."""
    return np.isin(time_block(n), rng.choice(PIECES, size=held_blocks(val_fraction), replace=False))


def time_folds(val_fraction: float, rng: np.random.Generator) -> list[np.ndarray]:
    """The PIECES time blocks in folds of ``held_blocks(val_fraction)`` blocks each, drawn at
    random: PIECES // held folds (five for 0.2, every block held out once), no block in two."""
    held = held_blocks(val_fraction)
    if held == 0:
        return []
    order = rng.permutation(PIECES)
    return [np.sort(order[k * held:(k + 1) * held]) for k in range(PIECES // held)]


def _at_most(rows: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """At most n of ``rows`` (sorted), drawn at random."""
    return rows if rows.size <= n else np.sort(rng.choice(rows, size=n, replace=False))


def balanced(rows: np.ndarray, labels: np.ndarray, n_target: int, rng: np.random.Generator) -> np.ndarray:
    """At most ``n_target`` of ``rows``, the same number from every label group (labels >= 0)."""
    rows = rows[labels[rows] >= 0]
    if rows.size <= n_target:
        return np.sort(rows)
    groups = np.unique(labels[rows])
    by_group = [rows[labels[rows] == g] for g in groups]
    sizes = np.array([r.size for r in by_group])
    # the largest per-group cap that keeps the total within n_target (small groups give all)
    lo, hi = 0, int(sizes.max())
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if np.minimum(sizes, mid).sum() <= n_target:
            lo = mid
        else:
            hi = mid - 1
    cap = max(lo, 1)
    picked = [r if r.size <= cap else rng.choice(r, size=cap, replace=False) for r in by_group]
    return np.sort(np.concatenate(picked))


def select(qd: np.ndarray, *, val_fraction: float = 0.2, max_samples: int | None = 2500, balance: bool = True,
           rng: np.random.Generator, keep: np.ndarray | None = None, moving: np.ndarray | None = None) -> Selection:
    """Training and validation rows for a log with velocity ``qd`` (n,).

    ``max_samples`` bounds training plus validation rows after balancing (None: no bound);
    ``keep`` (bool (n,)) restricts the rows that may be used at all. With ``balance``, a log
    without velocity levels trains on the rows ``moving`` (bool (n,); default ``keep``) and
    validates on whole blocks of time (mode "moving").
    """
    if not 0 <= val_fraction < 1:
        raise ValueError("val_fraction must be in [0, 1)")
    qd = np.asarray(qd, dtype=np.float64)
    n = qd.size
    usable = np.ones(n, dtype=bool) if keep is None else np.asarray(keep, dtype=bool)
    if balance:
        labels, mode = velocity_groups(qd[usable] if keep is not None else qd)
        if keep is not None:
            full = np.full(n, -1, dtype=np.int64)
            full[usable] = labels
            labels = full
        if mode != "levels":
            rows = usable if moving is None else np.asarray(moving, dtype=bool)
            return _in_time_blocks(rows, val_fraction, max_samples, rng)
    else:
        labels, mode = np.where(usable, 0, -1).astype(np.int64), "all"
    # runs: constant-velocity stretches for discrete levels, else stretches of usable rows
    run_labels = labels if mode == "levels" else np.where(usable, 0, -1)
    val_mask = split_segments(run_labels, val_fraction, rng)
    rows = np.flatnonzero(usable & (labels >= 0))
    train_rows, val_rows = rows[~val_mask[rows]], rows[val_mask[rows]]
    groups = int(np.unique(labels[labels >= 0]).size)
    if balance and max_samples is not None:
        n_val = int(round(max_samples * val_fraction)) if val_rows.size else 0
        train_rows = balanced(train_rows, labels, max_samples - n_val, rng)
        val_rows = balanced(val_rows, labels, n_val, rng)
    if train_rows.size == 0:
        raise DataError("no rows left to train on")
    blocks = np.where(usable & (labels >= 0), pieces(run_labels), -1)
    return Selection(train=train_rows, val=val_rows, blocks=blocks, mode=mode, groups=groups)


def _in_time_blocks(moving: np.ndarray, val_fraction: float, max_samples: int | None,
                    rng: np.random.Generator) -> Selection:
    """Mode "moving": the rows ``moving`` (bool (n,)) of whole time blocks (``time_blocks``)."""
    val_mask = time_blocks(moving.size, val_fraction, rng)
    train_rows, val_rows = np.flatnonzero(moving & ~val_mask), np.flatnonzero(moving & val_mask)
    if max_samples is not None and train_rows.size + val_rows.size > max_samples:
        n_val = int(round(max_samples * val_rows.size / (train_rows.size + val_rows.size)))
        train_rows, val_rows = _at_most(train_rows, max_samples - n_val, rng), _at_most(val_rows, n_val, rng)
    if train_rows.size == 0:
        raise DataError("no rows left to train on")
    blocks = np.where(moving, time_block(moving.size), -1)
    return Selection(train=train_rows, val=val_rows, blocks=blocks, mode="moving", groups=held_blocks(val_fraction))
