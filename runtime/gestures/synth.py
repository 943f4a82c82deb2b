"""Two-level Markov-random-field synthesis of gesture tracks from speech intensity (Ju & Lee 2008, §5.1).

The reference database (kind ``gesture_db``, written offline by
``facepuppet build-gestures``) holds reference tracks at the animation rate:
per frame the normalised speech intensity, the lips P(t), the mood blend
weights c(t), the regional residual features D_j(t) (brows, eyes, the rest)
and the head pose. :class:`GestureSynth` generates new tracks for a new voice,
one frame per :meth:`GestureSynth.step`. Each feature group picks, per frame,
a reference frame i by the §5.1 distance over the h preceding frames

    dist(i) = α/h Σ_{l=0}^{h-1} (s(t-l) - s_ref(i-l))²                  speech match
            + (1-α)/h Σ_{l=1}^{h} |x(t-l) - x_ref(i-l)|²                continuity
            + β |c(t-1) - c_ref(i)|²                                     level 2 only

and draws among the ``n_candidates`` best with probability ∝ exp(-dist / σ).

* Continuity is measured in the group's feature space itself: the features,
  divided by their reference std, rotated onto their principal axes and kept
  up to ``variance`` (default 95 %) of the group's variance (a rotation keeps
  distances, so this is the full-dimensional distance up to the dropped 5 %).
* The natural successor (the reference frame after the last pick, same take)
  has zero continuity cost by definition: consecutive reference frames are a
  perfect continuation. So picks form runs of consecutive reference frames
  and jump only where another frame's history matches the synthesised one
  well enough to win the draw; :attr:`GestureSynth.run_lengths` measures it.
* Recently shown frames are barred in every group but the lips (mood,
  brows, eyes, rest, head; ``recent`` frames, default 150 = 5 s at 30 fps):
  a candidate frame the group showed within the last ``recent`` steps costs
  ``RECENT_PENALTY`` more, so it wins only when every candidate is recent.
  (The lips follow the voice, and the few frames of its silence and loud
  intensity bins must stay reachable, so they are not barred.) Without it the chain falls into short loops: in a still
  stretch (eyes open, nothing moving) the window h frames back matches the
  current one almost perfectly, so "jump back h frames" is as cheap as the
  successor and the group replays the same second for minutes (measured on
  the real database: one seed spent 87 % of 10 minutes cycling through 9
  frames of a 5 s take, blinking 2.4/min against 18.4/min in the source).
  A loop now needs more than ``recent`` distinct frames, which a blink-free
  still stretch rarely has. Not in the paper (its database was one long
  take); the video-texture literature avoids short loops the same way.
* The eyes are shown whole (``whole``, default ("eyes",)): their channels are
  the pick's residual plus that same frame's mood c·B, not the mood pick's
  (why, measured: :mod:`facepuppet.runtime.gestures.output`).
* Two levels: level 1 is lips and mood (what the voice drives directly);
  level-2 groups (brows, eyes, rest, head) are conditioned on level 1 through
  the β term: the mood c of the level-1 pick made at the previous step
  (mood is a 41-frame-windowed, slow track, so one frame of lag is harmless
  and keeps the step to one vectorised pass). A group whose reference takes
  have no mood (the head from the marker takes) gets β = 0.

Paper symbols -> code names
---------------------------
==============  ==================================================
t               ``self._t`` (frames synthesised so far)
s(t)            normalised speech intensity, ``a`` / ``self._a_hist``
P(t)            group ``lips`` (absolute ARKit lip/jaw weights)
c(t)            group ``mood`` (blend weights; expression ``c @ blend_basis``)
D_j(t)          groups ``brows``, ``eyes``, ``rest`` (residuals), ``head``
x(t)            a group's features in its principal axes, ``self._desc``
h               ``history`` (default 10 frames)
α               ``alpha`` (speech weight), per group
β               ``beta`` (level-2 weight of the level-1 mood match)
σ               ``sigma``
2-4 candidates  ``n_candidates``
(not in paper)  ``recent`` (frames a shown frame is barred)
(not in paper)  ``whole`` (groups shown with their own frame's c·B)
==============  ==================================================

Indexing (why the step is < 0.1 ms): the full distance is evaluated only on a
small candidate set per group (the successor of the last pick, its continuity
neighbours and frames of the current intensity's bin; :mod:`facepuppet.runtime.gestures.candidates`).
The weighted windows of every frame are one preallocated matrix, so a step is
one gather, one squared difference and one matrix-vector product for all groups
at once; the draw among the best candidates is a Gumbel-max (one random call
for all groups), and the output is a gather of one precomputed row per group
(its features, or for the mood group its expression c·B; :mod:`facepuppet.runtime.gestures.output`)
summed by one product.
About 30 NumPy calls per step, ~60-80 µs on a loaded 2-core machine.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from facepuppet.runtime.errors import UsageError
from facepuppet.runtime.gestures.candidates import N_BINS, build_candidates
from facepuppet.runtime.gestures.output import output_table
from facepuppet.runtime.gestures.speaker_normaliser import SILENCE_Z, SpeakerNormaliser
from facepuppet.runtime.gestures.tables import GROUPS, LEVEL1

if TYPE_CHECKING:
    from facepuppet.runtime.files.tables import Tables

RECENT_PENALTY = 1e4  # added to a recently shown candidate's distance (distances are O(1); sentinels ~1e6)
WHOLE_GROUPS = ("eyes",)  # groups whose channels show one reference frame whole (own residual + own c·B)


def _principal_axes(x: np.ndarray, ok: np.ndarray, variance: float, max_dims: int) -> np.ndarray:
    """x (n, d) centred on its ``ok`` rows and projected on the fewest axes holding ``variance``."""
    xc = x - x[ok].mean(0)
    _, sv, vt = np.linalg.svd(xc[ok], full_matrices=False)
    frac = np.cumsum(sv ** 2) / max(float(np.sum(sv ** 2)), 1e-30)
    r = min(int(np.searchsorted(frac, variance - 1e-12)) + 1, max_dims, len(sv))
    return xc @ vt[:r].T


class GestureSynth:
    """Frame-by-frame two-level MRF synthesis of gesture tracks from speech intensity (Ju & Lee §5.1).

    Parameters
    ----------
    db : Tables of kind ``gesture_db`` (see :func:`load_gesture_db`)
    seed : int, seed of the candidate draws; same seed + same input = same output
    style : dict group -> take name, restricts a group to one take (a palette of styles)
    history : int, h, frames of history in the distance
    alpha : float or dict group -> float, weight α of speech match against continuity
    beta : float, level-2 weight of the match to level 1's mood (0: the levels are independent)
    sigma : float, σ of exp(-dist / σ); 0 picks the best candidate
    n_candidates : int, how many of the best candidates are drawn from (2-4 in the paper)
    n_neighbours, n_speech : int, jump candidates per frame by continuity, and per intensity bin
    variance : float in (0, 1], share of each group's variance kept by the continuity features
    recent : int, frames; a reference frame a group (not the lips) showed within the last ``recent`` steps is
        barred (``RECENT_PENALTY``) so that the picks cannot loop over a short still stretch (0: off)
    normaliser : SpeakerNormaliser or None (default: one from the db's speaker stats and gate)
    whole : groups (stochastic: brows, eyes, rest) whose channels are shown whole: the pick's residual plus the
        same frame's mood c·B, with no mood-pick contribution (default ``WHOLE_GROUPS``: a blink is one
        reference moment; () sums the mood pick's c·B into every channel, the paper's plain composition)
    """

    def __init__(self, db: Tables, seed: int = 0, style: Mapping[str, str] | None = None, history: int = 10,
                 alpha: float | Mapping[str, float] | None = None, beta: float = 0.5, sigma: float = 0.01,
                 n_candidates: int = 3, n_neighbours: int = 8, n_speech: int = 6, variance: float = 0.95,
                 max_dims: int = 8, normaliser: SpeakerNormaliser | None = None, recent: int = 150,
                 whole: Sequence[str] = WHOLE_GROUPS) -> None:
        if (history < 1 or n_candidates < 1 or sigma < 0 or not 0 < variance <= 1 or beta < 0
                or recent < 0):
            raise UsageError(f"GestureSynth: expected history >= 1, n_candidates >= 1, sigma >= 0, beta >= 0, "
                             f"0 < variance <= 1, recent >= 0; got {history}, {n_candidates}, {sigma}, {beta}, "
                             f"{variance}, {recent}")
        self.h, self.sigma, self.n_candidates, self.seed = history, float(sigma), n_candidates, seed
        self.recent = int(recent)
        self.whole = tuple(whole)
        if not set(self.whole) <= {"brows", "eyes", "rest"}:
            raise ValueError(f"GestureSynth.whole: expected groups among ('brows', 'eyes', 'rest'), got {self.whole}")
        self.names = tuple(db.channels["features"])
        self.takes = tuple(db.channels["takes"])
        feats = np.asarray(db["features"], np.float64)
        self._feats = np.asarray(db["features"], np.float32)
        self._intensity = np.asarray(db["intensity"], np.float64)
        self._basis = np.asarray(db["blend_basis"], np.float32)
        group_of = np.asarray(db["feature_group"])
        scale = np.maximum(np.asarray(db["feature_scale"], np.float64), 1e-6)
        take = np.asarray(db["frame_take"])
        avail = np.asarray(db["available"])
        settings = db.settings
        alpha = settings.get("alpha", {}) if alpha is None else alpha
        style = dict(style or {})
        for g, take_name in style.items():
            if g not in GROUPS or take_name not in self.takes:
                raise UsageError(f"style: expected group in {GROUPS} and take in {self.takes}, got {g}={take_name}")
        self.normaliser = normaliser or SpeakerNormaliser(
            settings.get("speaker_mean_db", -30.0), settings.get("speaker_std_db", 8.0),
            settings.get("speaker_gate_db", -60.0))
        n, h = len(take), history
        start = np.r_[True, take[1:] != take[:-1]]
        pos = np.arange(n) - np.maximum.accumulate(np.where(start, np.arange(n), 0))  # frames since take start
        last = np.r_[take[1:] != take[:-1], True]
        self.groups = [g for gi, g in enumerate(GROUPS) if (group_of == gi).any() and avail[:, gi].any()]
        G = len(self.groups)
        self._gidx = np.arange(G)
        self._cols = [np.flatnonzero(group_of == GROUPS.index(g)) for g in self.groups]
        self._alpha = np.array([float(alpha.get(g, 0.9 if g in LEVEL1 else 0.5)) if isinstance(alpha, dict)
                                else float(alpha) for g in self.groups])
        self._valid = np.zeros((G, n), bool)
        descs = []
        for k, g in enumerate(self.groups):
            ok = avail[:, GROUPS.index(g)] & (pos >= h)
            if g in style:
                ok &= take == self.takes.index(style[g])
            if not ok.any():
                raise UsageError(f"GestureSynth: group {g!r} has no reference frame with {h} frames of history"
                                 + (f" in take {style[g]!r}" if g in style else ""))
            self._valid[k] = ok
            descs.append(_principal_axes(feats[:, self._cols[k]] / scale[self._cols[k]], ok, variance, max_dims))
        self.dims = {g: d.shape[1] for g, d in zip(self.groups, descs)}
        R = max(self.dims.values())
        self._desc = np.zeros((n, G, R))
        for k, d in enumerate(descs):
            self._desc[:, k, :d.shape[1]] = d
        # level-2 conditioning features: the normalised mood c(i) (zeros where a take has no mood)
        self._km = self.groups.index("mood") if "mood" in self.groups else -1
        if self._km >= 0:
            mc = self._cols[self._km]
            self._moodf = np.where(avail[:, [GROUPS.index("mood")]], feats[:, mc] / scale[mc], 0.0)
        else:
            self._moodf = np.zeros((n, 0))
        has_mood = avail[:, GROUPS.index("mood")]
        self._beta = np.array([beta if (g not in LEVEL1 and self._km >= 0 and has_mood[self._valid[k]].all())
                               else 0.0 for k, g in enumerate(self.groups)])
        self._T_raw = build_candidates(self._desc, self._valid, self._intensity, last, h, n_neighbours, n_speech)
        self._prepare_windows()
        self.out_names = self._output_names()
        self.additions = np.zeros(len(self.out_names), np.float32)
        self._ones_g = np.ones(len(self.groups), np.float32)
        self.reset()

    def _prepare_windows(self) -> None:
        """Flat tables for the step: one row per (group, frame) holding its weighted history window.

        Row ``g (n + 1) + i`` is [√(α/h) s_ref(i-h+1 .. i), √β c_ref(i-1), √((1-α)/h) x_ref(i-h .. i-1)]
        (the mood term compares with the level-1 pick of the step before, so with frame i - 1), so that the
        squared distance to the query row, split into its speech+mood and continuity columns, gives §5.1;
        row ``g (n + 1) + n`` is a sentinel far from everything.
        """
        G, n, h = len(self.groups), len(self._intensity), self.h
        R, Cm = self._desc.shape[2], self._moodf.shape[1]
        idx = np.arange(n)
        S = self._intensity[np.clip(idx[:, None] + np.arange(-h + 1, 1), 0, n - 1)]        # (n, h)
        win = self._desc[np.clip(idx[:, None] + np.arange(-h, 0), 0, n - 1)]               # (n, h, G, R)
        M_prev = self._moodf[np.clip(idx - 1, 0, n - 1)]                                    # (n, Cm)
        self._wa, self._wc = np.sqrt(self._alpha / h), np.sqrt((1.0 - self._alpha) / h)
        self._wm = np.sqrt(self._beta)
        D = h + Cm + h * R
        X = np.full((G, n + 1, D), 1e3)
        for k in range(G):
            X[k, :n, :h] = self._wa[k] * S
            X[k, :n, h:h + Cm] = self._wm[k] * M_prev
            X[k, :n, h + Cm:] = self._wc[k] * win[:, :, k, :].reshape(n, -1)
        self._X = X.reshape(G * (n + 1), D).astype(np.float32)
        self._c0 = h + Cm                                   # first continuity column
        self._query = np.zeros((G, D), np.float32)
        K = self._T_raw.shape[2]
        self._M = M = 2 * K
        self._T = self._T_raw.reshape(-1, K)
        self._rows = np.zeros(2 * G, np.int64)
        self._goff_T = self._gidx * (n + N_BINS)
        self._goff_X = np.repeat(self._gidx * (n + 1), M)
        self._row_off = (self._gidx * M)[:, None]
        self._m = min(self.n_candidates, M)
        self._n = n
        self._bin_scale = N_BINS / (-2 * SILENCE_Z)
        self._wa_col = self._wa[:, None].astype(np.float32)
        self._wm_col = self._wm[:, None].astype(np.float32)
        self._moodf = self._moodf.astype(np.float32)
        self._ones = np.ones(D, np.float32)            # the squared differences summed by one matrix-vector product
        self._dist = np.zeros(G * M, np.float32)
        self._goff_n = self._gidx * n                  # row of (group, frame) in the group-major tables below
        # the continuity features pre-weighted, group-major (row g n + i): the history ring holds these
        self._desc_w = (self._desc * self._wc[None, :, None]).transpose(1, 0, 2).reshape(G * n, -1).astype(np.float32)
        self._last_pick = np.zeros(G, np.int64)
        self._is_jump = np.zeros(G, bool)
        # step at which each (group, frame) was last shown, rows as in _X (g (n + 1) + i); sentinels never shown
        self._seen = np.zeros(G * (n + 1), np.int64)
        self._goff_seen = self._gidx * (n + 1)
        self._cand_seen = np.zeros(G * M, np.int64)
        self._barred = np.zeros(G * M, bool)
        self._penalty = np.zeros(G * M, np.float32)
        self._bar = np.repeat([0.0 if g == "lips" else RECENT_PENALTY for g in self.groups], M).astype(np.float32)

    def _output_names(self) -> tuple[str, ...]:
        """Output channels; sets the output row tables (:func:`facepuppet.runtime.gestures.output.output_table`)
        and ``_mood``."""
        out = output_table(self.groups, self._cols, self.names, self._feats, self._basis, self.whole)
        self._mood, self._out_table, self._whole_k, self._own_table = out.mood, out.table, out.whole_k, out.own_table
        self._out_rows = np.zeros((len(self.groups), len(out.names)), np.float32)
        self._own_off = np.arange(len(self._whole_k)) * len(self._feats)
        return out.names

    def reset(self, start: int | None = None) -> None:
        """Restart the sequence: each group at reference frame ``start`` (default: a seeded random valid frame).

        The synthesised history is filled from the reference frames before the
        start, and the speech history with the reference intensity there.
        """
        self.rng = np.random.Generator(np.random.PCG64(self.seed))
        G, h = len(self.groups), self.h
        picks = []
        for k in range(G):
            valid = np.flatnonzero(self._valid[k])
            p = int(start) if start is not None else int(valid[self.rng.integers(len(valid))])
            if not 0 <= p < len(self._intensity) or not self._valid[k, p]:
                raise ValueError(f"reset: frame {p} is not a valid start for group {self.groups[k]!r} "
                                 f"(needs {h} frames of history in its take)")
            picks.append(p)
        self._pick = np.array(picks, np.int64)
        # ring buffers of length 2h, written twice so that [pos : pos + h] is the history in order
        self._z_hist = np.zeros((G, 2 * h, self._desc.shape[2]), np.float32)
        self._a_hist = np.zeros(2 * h, np.float32)
        for i, offset in enumerate(range(-h + 1, 1)):  # frames before the start pick, oldest first
            self._z_hist[:, i] = self._z_hist[:, i + h] = self._desc_w.take(self._pick + offset + self._goff_n, 0)
            self._a_hist[i] = self._a_hist[i + h] = self._intensity[self._pick[0] + offset]
        self._apos = self._zpos = 0
        self._t = 0
        self._seen[:] = -(self.recent + 1)          # nothing shown yet
        self._seen[self._pick + self._goff_seen] = 0
        self._jumps = np.zeros(G, np.int64)
        self._emit()

    def step(self, audio_db: float) -> np.ndarray:
        """Advance one animation frame with the voice level ``audio_db`` (dBFS, NaN = silence).

        Returns
        -------
        additions : ndarray of shape (len(out_names),), float32, named by ``out_names``; reused between calls
        """
        return self.step_normalised(self.normaliser(audio_db))

    def step_normalised(self, a: float) -> np.ndarray:
        """:meth:`step` for an already normalised intensity ``a`` (z-score)."""
        h, G, c0 = self.h, len(self.groups), self._c0
        ap = self._apos
        self._a_hist[ap] = self._a_hist[ap + h] = a
        ap = self._apos = (ap + 1) % h
        q, zp = self._query, self._zpos
        np.multiply(self._a_hist[ap:ap + h], self._wa_col, out=q[:, :h])                    # s(t-h+1 .. t)
        if self._km >= 0:
            np.multiply(self._moodf[self._pick[self._km]], self._wm_col, out=q[:, h:c0])    # c(t-1), level 1
        q[:, c0:] = self._z_hist[:, zp:zp + h].reshape(G, -1)                               # x(t-h .. t-1)
        b = min(max(int((a - SILENCE_Z) * self._bin_scale), 0), N_BINS - 1)
        rows = self._rows
        np.add(self._goff_T, self._pick, out=rows[0::2])  # successor + continuity neighbours of the last pick
        np.add(self._goff_T, self._n + b, out=rows[1::2])  # frames of the current intensity's bin
        cand = self._T.take(rows, 0).ravel()     # (G * M,) frame indices, grouped by group
        diff = self._X.take(cand + self._goff_X, 0).reshape(G, self._M, -1)
        diff -= q[:, None, :]
        diff *= diff
        diff[:, 0, c0:] = 0.0  # the natural successor continues perfectly: no continuity cost
        # §5.1: α/h Σ (s - s_ref)² + β |c - c_ref|² + (1-α)/h Σ |x - x_ref|² (weights folded into the rows)
        dist = np.matmul(diff.reshape(G * self._M, -1), self._ones, out=self._dist)
        if self.recent > 0:  # bar the frames shown in the last `recent` steps (no short loops)
            cs = self._cand_seen
            np.add(cand, self._goff_X, out=cs)
            self._seen.take(cs, out=cs)
            np.greater_equal(cs, self._t - self.recent + 1, out=self._barred)
            np.multiply(self._barred, self._bar, out=self._penalty)
            dist += self._penalty
        dist = dist.reshape(G, self._M)
        m = self._m
        if self.sigma > 0 and m > 1:
            # §5.1: among the m best, P(candidate) ∝ exp(-dist / σ), drawn by the Gumbel-max trick:
            # argmax(-dist + σ g), g ~ Gumbel(0, 1), has exactly that distribution
            best = dist.argsort(1, kind="stable")[:, :m] + self._row_off
            score = self.rng.gumbel(0.0, self.sigma, (G, m))
            score -= dist.take(best)
            pick = cand.take(best.take(self._gidx * m + score.argmax(1)))
        else:
            pick = cand.take(dist.argmin(1) + self._row_off[:, 0])
        np.add(self._pick, 1, out=self._last_pick)
        np.not_equal(pick, self._last_pick, out=self._is_jump)
        self._jumps += self._is_jump
        self._pick = pick
        idx = pick + self._goff_n
        self._z_hist[:, zp] = self._z_hist[:, zp + h] = self._desc_w.take(idx, 0)
        self._zpos = (zp + 1) % h
        self._t += 1
        self._seen[pick + self._goff_seen] = self._t
        return self._emit(idx)

    def _emit(self, idx: np.ndarray | None = None) -> np.ndarray:
        """Sum the picked frames' output rows (features, and the mood expression c·B) into ``additions``.

        idx : (G,) int64, rows ``pick + g n`` of the output table (default: from the current picks)
        """
        if idx is None:
            idx = self._pick + self._goff_n
        np.take(self._out_table, idx, 0, out=self._out_rows)
        return np.matmul(self._ones_g, self._out_rows, out=self.additions)

    @property
    def mood_part(self) -> np.ndarray:
        """The mood expressions c·B inside ``additions`` now, (len(out_names),) float32, a new array.

        The mood pick's c·B on the other channels, each whole group's own pick's c·B on its channels
        (zeros without mood), so ``additions - mood_part`` is the residuals of the picks. Computed on
        demand (only the "add" mode of the layer needs it), not in :meth:`step`.
        """
        if self._mood is None:
            return np.zeros(len(self.out_names), np.float32)
        part = self._out_rows[self._mood[0]].copy()
        if len(self._whole_k):
            part += self._own_table.take(self._pick.take(self._whole_k) + self._own_off, 0).sum(0)
        return part

    @property
    def n_reference_frames(self) -> int:
        """Frames of the reference database."""
        return len(self._intensity)

    def group_columns(self, group: str) -> np.ndarray:
        """Indices into :attr:`names` of the feature columns of ``group`` (ValueError for an unknown group)."""
        if group not in self.groups:
            raise ValueError(f"GestureSynth.group_columns: expected one of {self.groups}, got {group!r}")
        return self._cols[self.groups.index(group)].copy()

    def pick(self, group: str) -> int:
        """The reference frame ``group`` shows now (its last pick)."""
        return int(self._pick[self.groups.index(group)])

    @property
    def picks(self) -> dict[str, int]:
        """The reference frame each group shows now."""
        return {g: int(p) for g, p in zip(self.groups, self._pick)}

    @property
    def run_lengths(self) -> dict[str, float]:
        """Mean run of consecutive reference frames per group since :meth:`reset` (frames per jump)."""
        return {g: self._t / max(int(j), 1) for g, j in zip(self.groups, self._jumps)}
