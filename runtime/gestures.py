"""Gesture layer: speech-driven stochastic facial gestures (Ju & Lee 2008, §5.1), per frame.

The reference database (kind ``gesture_db``, written offline by
``facepuppet build-gestures``) holds reference tracks at the animation rate:
per frame the normalised speech intensity, the lips P(t), the mood blend
weights c(t), the regional residual features D_j(t) (brows, eyes, the rest)
and the head pose. :class:`GestureSynth` generates new tracks for a new voice,
one frame per :meth:`GestureSynth.step`, by the Markov-random-field rule of
§5.1: each feature group picks the reference frame whose h preceding frames
best match (speech intensity, weight α) and continue (its own synthesised
history, weight 1 - α) the new sequence, choosing among the ``n_candidates``
best with probability ∝ exp(-dist / σ). Two levels: level 1 is lips and mood
(what the voice drives directly), level 2 the regional gestures and head.

Paper symbols -> code names
---------------------------
==============  ==================================================
t               ``self._t`` (frames synthesised so far)
s(t)            normalised speech intensity, ``a`` / ``self._a_hist``
P(t)            group ``lips`` (absolute ARKit lip/jaw weights)
c(t)            group ``mood`` (blend weights; expression ``c @ blend_basis``)
D_j(t)          groups ``brows``, ``eyes``, ``rest`` (residuals), ``head``
h               ``history`` (default 10 frames)
α               ``alpha`` (speech weight), per group
σ               ``sigma``
2-4 candidates  ``n_candidates``
==============  ==================================================

Indexing (why the step is < 0.1 ms): the full §5.1 distance is evaluated on a
small candidate set per group, built once at construction: the natural
continuation of the previous pick, its ``n_neighbours`` nearest frames in
history space (kd-tree, :class:`scipy.spatial.cKDTree`) and ``n_speech``
frames from the bin of the current intensity. Continuity is measured on a
per-group PCA descriptor (``descriptor_dims`` dims) of the features.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from .channels import canonical
from .frames import Frame
from .geometry import euler_to_quat
from .tables import Section, TableSchema, TablesError, load_tables, register_schema

GROUPS = ("lips", "mood", "brows", "eyes", "rest", "head")
LEVEL1 = ("lips", "mood")
HEAD_FEATURES = ("headYaw", "headPitch", "headRoll", "headX", "headY", "headZ")
SILENCE_Z = -3.0  # normalised intensity of silence (floor)

GESTURE_DB_SCHEMA = register_schema(TableSchema(
    kind="gesture_db",
    sections={
        "intensity": Section("float32", ("n_frames",), "speech intensity s(t), per-speaker z-score of dB"),
        "features": Section("float32", ("n_frames", "n_features"), "P(t), c(t), D_j(t), head per frame"),
        "feature_group": Section("int32", ("n_features",), "group id of each feature (index into GROUPS)"),
        "feature_scale": Section("float32", ("n_features",), "per-feature std, for the distances"),
        "blend_basis": Section("float32", ("n_basis", "n_features"), "whole-face expressions B (§4.1)"),
        "frame_take": Section("int32", ("n_frames",), "take index of each frame"),
        "available": Section("bool", ("n_frames", 6), "whether the frame's take provides each group"),
    },
    channels=("features", "takes", "groups"),
    channel_dims={"features": "n_features"},
))


def load_gesture_db(path):
    """Load and check a ``gesture_db`` tables file; TablesError naming the field otherwise."""
    db = load_tables(path, kind="gesture_db")
    if list(db.channels["groups"]) != list(GROUPS):
        raise TablesError(path, "channels.groups", f"expected {list(GROUPS)}, found {db.channels['groups']}")
    n_takes = len(db.channels["takes"])
    take = db["frame_take"]
    if take.size and (take.min() < 0 or take.max() >= n_takes):
        raise TablesError(path, "frame_take", f"expected take indices in [0, {n_takes}), found "
                                              f"{take.min()}..{take.max()}")
    groups = db["feature_group"]
    if groups.size and (groups.min() < 0 or groups.max() >= len(GROUPS)):
        raise TablesError(path, "feature_group", f"expected group ids in [0, {len(GROUPS)})")
    return db


class SpeakerNormaliser:
    """dBFS -> per-speaker z-score, with running statistics of voiced frames.

    Parameters
    ----------
    mean_db, std_db : float, dBFS, starting estimate of the speaker's voiced level
    floor_db : float, dBFS; at or below it (or NaN: not measured) the frame is silence
    rate : float, weight of a new voiced frame in the running mean/variance (0: frozen)
    """

    def __init__(self, mean_db: float = -30.0, std_db: float = 8.0, floor_db: float = -60.0,
                 rate: float = 0.002):
        self.mean_db, self.var_db, self.floor_db, self.rate = float(mean_db), float(std_db) ** 2, floor_db, rate

    def __call__(self, level_db: float) -> float:
        if not (level_db > self.floor_db):  # NaN or silence
            return SILENCE_Z
        if self.rate > 0:
            d = level_db - self.mean_db
            self.mean_db += self.rate * d
            self.var_db += self.rate * (d * d - self.var_db)
        return max(SILENCE_Z, (level_db - self.mean_db) / math.sqrt(max(self.var_db, 1.0)))


class GestureSynth:
    """Frame-by-frame MRF synthesis of gesture tracks from speech intensity (Ju & Lee §5.1).

    Parameters
    ----------
    db : Tables of kind ``gesture_db`` (see :func:`load_gesture_db`)
    seed : int, seed of the candidate draws; same seed + same input = same output
    style : dict group -> take name, restricts a group to one take (a palette of styles)
    history : int, h, frames of history in the distance
    alpha : float or dict group -> float, weight α of speech match against continuity
    sigma : float, σ of exp(-dist / σ); 0 picks the best candidate
    n_candidates : int, how many of the best candidates are drawn from (2-4 in the paper)
    normaliser : SpeakerNormaliser or None (default: one started from the db's speaker stats)
    """

    def __init__(self, db, seed: int = 0, style=None, history: int = 10, alpha=None, sigma: float = 0.05,
                 n_candidates: int = 3, n_neighbours: int = 12, n_speech: int = 8, descriptor_dims: int = 2,
                 normaliser: SpeakerNormaliser | None = None):
        if history < 1 or n_candidates < 1 or sigma < 0:
            raise ValueError(f"GestureSynth: expected history >= 1, n_candidates >= 1, sigma >= 0; got "
                             f"{history}, {n_candidates}, {sigma}")
        self.h, self.sigma, self.n_candidates, self.seed = history, float(sigma), n_candidates, seed
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
                raise ValueError(f"style: expected group in {GROUPS} and take in {self.takes}, got {g}={take_name}")
        self.normaliser = normaliser or SpeakerNormaliser(settings.get("speaker_mean_db", -30.0),
                                                          settings.get("speaker_std_db", 8.0))
        n = len(take)
        start = np.r_[True, take[1:] != take[:-1]]
        pos = np.arange(n) - np.maximum.accumulate(np.where(start, np.arange(n), 0))  # frames since take start
        last = np.r_[take[1:] != take[:-1], True]
        self.groups = [g for gi, g in enumerate(GROUPS) if (group_of == gi).any() and avail[:, gi].any()]
        G, r, h = len(self.groups), descriptor_dims, history
        self._cols = [np.flatnonzero(group_of == GROUPS.index(g)) for g in self.groups]
        self._alpha = np.array([float(alpha.get(g, 0.9 if g in LEVEL1 else 0.5)) if isinstance(alpha, dict)
                                else float(alpha) for g in self.groups])
        # per-group PCA descriptor of the normalised features (continuity metric)
        self._desc = np.zeros((n, G, r))
        self._valid = np.zeros((G, n), bool)
        for k, g in enumerate(self.groups):
            x = feats[:, self._cols[k]] / scale[self._cols[k]]
            ok = avail[:, GROUPS.index(g)] & (pos >= h)
            if g in style:
                ok &= take == self.takes.index(style[g])
            if not ok.any():
                raise ValueError(f"GestureSynth: group {g!r} has no reference frame with {h} frames of history"
                                 + (f" in take {style[g]!r}" if g in style else ""))
            self._valid[k] = ok
            xc = x - x[ok].mean(0)
            _, _, vt = np.linalg.svd(xc[ok], full_matrices=False)
            d = xc @ vt[:r].T
            self._desc[:, k, :d.shape[1]] = d
        self._build_index(n_neighbours, n_speech, last)
        self._gidx = np.arange(G)
        self._prepare_windows()
        self.out_names = self._output_names()
        self.additions = np.zeros(len(self.out_names), np.float32)
        self.mood_part = np.zeros(len(self.out_names), np.float32)
        self.rng = np.random.Generator(np.random.PCG64(seed))
        self.reset()

    def _build_index(self, n_neighbours: int, n_speech: int, last: np.ndarray) -> None:
        """Candidate table per group: row p = continuation of p, its kd-tree neighbours, speech-bin frames."""
        G, n, h = len(self.groups), len(last), self.h
        K = n_neighbours + 1
        self._trans = np.zeros((G, n, K), np.int64)
        self._trans_pen = np.zeros((G, n, K))
        self._n_bins = 24
        self._sbin = np.zeros((G, self._n_bins, n_speech), np.int64)
        self._sbin_pen = np.zeros((G, self._n_bins, n_speech))
        lag_pick = np.unique(np.linspace(-h, -1, min(h, 5)).round().astype(int))
        bins = self._bin(self._intensity)
        for k in range(G):
            valid = np.flatnonzero(self._valid[k])
            window = np.stack([self._desc[np.clip(valid + l, 0, n - 1), k] for l in lag_pick], 1).reshape(len(valid), -1)
            tree = cKDTree(window)
            q = min(K + 2 * h, len(valid))
            _, nb = tree.query(window, k=q)
            nb = valid[np.asarray(nb).reshape(len(valid), q)]
            row_of = np.full(n, -1)
            row_of[valid] = np.arange(len(valid))
            for p in range(n):
                nxt = p + 1 if (not last[p] and p + 1 < n and self._valid[k, p + 1]) else -1
                anchor = nxt if nxt >= 0 else (p if row_of[p] >= 0 else valid[0])
                near = nb[row_of[anchor]]
                near = near[(np.abs(near - anchor) >= h) & (near != p)][:K - 1]
                row = ([nxt] if nxt >= 0 else []) + list(near)
                pen = [0.0] * len(row) + [np.inf] * (K - len(row))
                row = (row + [valid[0]] * K)[:K]
                self._trans[k, p], self._trans_pen[k, p] = row, pen
            for b in range(self._n_bins):
                members = valid[bins[valid] == b]
                if len(members) == 0:
                    self._sbin_pen[k, b] = np.inf
                    self._sbin[k, b] = valid[0]
                    continue
                pick = members[np.linspace(0, len(members) - 1, n_speech).round().astype(int)]
                self._sbin[k, b] = pick
                if len(members) < n_speech:
                    self._sbin_pen[k, b, len(members):] = np.inf

    def _bin(self, a):
        return np.clip(((np.asarray(a) + 3.0) / 6.0 * self._n_bins).astype(int), 0, self._n_bins - 1)

    def _prepare_windows(self) -> None:
        """Flat tables for the step: one row per (group, frame) holding its weighted history window.

        Row ``g (n + 1) + i`` is [√(α_g/h) s_ref(i-h+1 .. i), √((1-α_g)/h) D_ref(i-h .. i-1)], so one
        squared distance to the query row gives the §5.1 distance; row ``g (n + 1) + n`` is a sentinel
        (far from everything) that pads the candidate rows.
        """
        G, n, h = len(self.groups), len(self._intensity), self.h
        lag_s, lag_c = np.arange(-h + 1, 1), np.arange(-h, 0)   # speech t-h+1..t; continuity t-h..t-1
        idx = np.arange(n)
        S = self._intensity[np.clip(idx[:, None] + lag_s, 0, n - 1)]                 # (n, h)
        win = self._desc[np.clip(idx[:, None] + lag_c, 0, n - 1)]                   # (n, h, G, r)
        self._wa, self._wc = np.sqrt(self._alpha / h), np.sqrt((1.0 - self._alpha) / h)
        X = np.full((G, n + 1, h + win.shape[1] * win.shape[3]), 1e3)
        for k in range(G):
            X[k, :n, :h] = self._wa[k] * S
            X[k, :n, h:] = self._wc[k] * win[:, :, k, :].reshape(n, -1)
        self._X = X.reshape(G * (n + 1), -1)
        self._query = np.zeros((G, X.shape[2]))
        K = max(self._trans.shape[2], self._sbin.shape[2])
        pad = lambda a, p: np.where(np.isfinite(p), a, n)  # padded entries -> sentinel frame n
        T = np.full((G, n + self._n_bins, K), n, np.int64)
        T[:, :n, :self._trans.shape[2]] = pad(self._trans, self._trans_pen)
        T[:, n:, :self._sbin.shape[2]] = pad(self._sbin, self._sbin_pen)
        self._T = T.reshape(-1, K)
        self._rows = np.zeros(2 * G, np.int64)
        self._M = M = 2 * K
        self._goff_T = self._gidx * (n + self._n_bins)
        self._goff_X = np.repeat(self._gidx * (n + 1), M)
        self._grep = np.repeat(self._gidx, M)
        self._ones = np.ones(X.shape[2])
        self._row_off = (self._gidx * M)[:, None]

    def _output_names(self) -> tuple[str, ...]:
        """Output channels; sets the flat gather (``_out_group``, ``_out_cols``) and ``_mood``."""
        names: list[str] = []
        out_group, out_cols = [], []
        for k, g in enumerate(self.groups):
            if g == "mood":
                continue
            names += [self.names[c] for c in self._cols[k]]
            out_group += [k] * len(self._cols[k])
            out_cols += list(self._cols[k])
        self._mood = None
        if "mood" in self.groups:
            used = np.flatnonzero(np.abs(self._basis).sum(0) > 0)
            for c in used:
                if self.names[c] not in names:  # a mood-only channel: no residual feature, gather a zero
                    names.append(self.names[c])
                    out_group.append(self.groups.index("mood"))
                    out_cols.append(-1)
            dst = np.array([names.index(self.names[c]) for c in used], np.int64)
            self._mood = (self.groups.index("mood"), used, dst)
            self._basis_out = np.zeros((len(self._basis), len(names)), np.float32)
            self._basis_out[:, dst] = self._basis[:, used]
        self._n_feat = self._feats.shape[1] + 1
        self._feats_flat = np.concatenate([self._feats, np.zeros((len(self._feats), 1), np.float32)], 1).ravel()
        self._out_group = np.array(out_group, np.int64)
        self._out_cols = np.where(np.array(out_cols, np.int64) < 0, self._n_feat - 1, out_cols).astype(np.int64)
        return tuple(names)

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
            if not self._valid[k, p]:
                raise ValueError(f"reset: frame {p} is not a valid start for group {self.groups[k]!r} "
                                 f"(needs {h} frames of history in its take)")
            picks.append(p)
        self._pick = np.array(picks, np.int64)
        # ring buffers of length 2h, written twice so that [pos : pos + h] is the history in order
        self._z_hist = np.zeros((G, 2 * h, self._desc.shape[2]))
        self._a_hist = np.zeros(2 * h)
        for i, l in enumerate(range(-h + 1, 1)):
            self._z_hist[:, i] = self._z_hist[:, i + h] = self._desc[self._pick + l, self._gidx]
            self._a_hist[i] = self._a_hist[i + h] = self._intensity[self._pick[0] + l]
        self._apos = self._zpos = 0
        self._t = 0
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
        h, G, M, n = self.h, len(self.groups), self._M, len(self._intensity)
        self._a_hist[self._apos] = self._a_hist[self._apos + h] = a
        self._apos = (self._apos + 1) % h
        q = self._query
        q[:, :h] = self._a_hist[self._apos:self._apos + h] * self._wa[:, None]              # s(t-h+1 .. t)
        q[:, h:] = self._z_hist[:, self._zpos:self._zpos + h].reshape(G, -1) * self._wc[:, None]  # D(t-h..t-1)
        b = min(max(int((a + 3.0) / 6.0 * self._n_bins), 0), self._n_bins - 1)
        rows = self._rows
        rows[0::2] = self._goff_T + self._pick   # continuation + kd-tree neighbours of the last pick
        rows[1::2] = self._goff_T + n + b        # frames of the current intensity's bin
        cand = self._T.take(rows, 0).ravel()     # (G * M,) frame indices, grouped by group
        # Ju & Lee §5.1: α (1/h) Σ_{l=0}^{h-1} (s(t-l) - s_ref(i-l))² + (1-α) (1/h) Σ_{l=1}^{h} |D(t-l) - D_ref(i-l)|²
        dist = (np.square(self._X.take(cand + self._goff_X, 0) - q.take(self._grep, 0)) @ self._ones).reshape(G, M)
        m = min(self.n_candidates, M)
        order = np.argsort(dist, axis=1, kind="stable")[:, :m] + self._row_off
        if self.sigma > 0 and m > 1:
            best = dist.take(order)
            w = np.exp((best[:, :1] - best) / self.sigma)  # §5.1: P(candidate) ∝ exp(-dist / σ)
            c = np.cumsum(w, 1)
            choice = np.minimum((c < self.rng.random(G)[:, None] * c[:, -1:]).sum(1), m - 1)
            self._pick = cand.take(order.take(self._gidx * m + choice))
        else:
            self._pick = cand.take(order[:, 0])
        self._z_hist[:, self._zpos] = self._z_hist[:, self._zpos + h] = self._desc[self._pick, self._gidx]
        self._zpos = (self._zpos + 1) % h
        self._t += 1
        return self._emit()

    def _emit(self) -> np.ndarray:
        """Write the picked frames' features (and the mood expression c·B) into ``additions``."""
        out = self.additions
        np.take(self._feats_flat, self._pick.take(self._out_group) * self._n_feat + self._out_cols, out=out)
        if self._mood is not None:
            k, used, dst = self._mood
            c = self._feats_flat.take(self._pick[k] * self._n_feat + self._cols[k])
            np.matmul(c, self._basis_out, out=self.mood_part)  # §4.1: blend expression c·B
            out += self.mood_part
        return out

    @property
    def picks(self) -> dict[str, int]:
        """The reference frame each group shows now."""
        return {g: int(p) for g, p in zip(self.groups, self._pick)}


class GestureLayer:
    """Combine synthesised gestures with tracked frames; a frame-loop pipeline ``(frame, t) -> frame``.

    Modes: ``"add"`` adds the stochastic residuals (brows, eyes, rest) and the
    head motion to the tracked face and fills channels the tracker lost (NaN)
    with the synthesised absolute value; ``"voice"`` animates the face from the
    voice alone (lips from intensity, mood, gestures, head). With no tracked
    frame yet, "add" behaves like "voice".

    Parameters
    ----------
    synth : GestureSynth
    fps : float, animation rate of the database (frames per second)
    mode : "add" or "voice"
    level : callable t -> dBFS or None; default: the frame's ``audio_level``
    inner : callable (frame, t) -> frame or None, applied to the tracked frame first
    """

    def __init__(self, synth: GestureSynth, fps: float, mode: str = "add", level=None, inner=None):
        if mode not in ("add", "voice"):
            raise ValueError(f"GestureLayer.mode: expected 'add' or 'voice', got {mode!r}")
        if not fps > 0:
            raise ValueError(f"GestureLayer.fps: expected a positive number, got {fps}")
        self.synth, self.fps, self.mode, self.level, self.inner = synth, float(fps), mode, level, inner
        self._k = 0  # animation frames synthesised
        self._last: Frame | None = None
        self._names = tuple(canonical(n) for n in synth.out_names)
        self._head = [self._names.index(n) if n in self._names else -1 for n in HEAD_FEATURES]
        self._face = np.array([i for i, n in enumerate(self._names) if n not in HEAD_FEATURES], np.int64)
        self._face_names = tuple(self._names[i] for i in self._face)
        stochastic = {synth.names[c] for g in ("brows", "eyes", "rest") if g in synth.groups
                      for c in synth._cols[synth.groups.index(g)]}
        self._residual = np.array([canonical(synth.out_names[i]) in {canonical(n) for n in stochastic}
                                   for i in self._face])
        self._maps: dict = {}

    def __call__(self, frame: Frame | None, t: float) -> Frame | None:
        if self.inner is not None:
            frame = self.inner(frame, t)
        if frame is not None:
            self._last = frame
        while self._k <= t * self.fps + 1e-9:  # one synth step per animation frame up to t
            src = self._last
            db = self.level(self._k / self.fps) if self.level is not None else (
                src.audio_level if src is not None else math.nan)
            self.synth.step(db)
            self._k += 1
        return self.compose(self._last if self.mode == "add" else None, t)

    def compose(self, tracked: Frame | None, t: float) -> Frame:
        """The output frame for the current synthesised state over ``tracked`` (None: voice only)."""
        add = self.synth.additions
        face = add[self._face]
        residual = face - self.synth.mood_part[self._face]
        rot, trans = self._pose(add)
        if tracked is None or tracked.weights is None:
            return Frame(t, source="gestures", channels=self._face_names, weights=face,
                         head_rotation=rot, head_translation=trans,
                         audio_level=math.nan if tracked is None else tracked.audio_level)
        names, idx_t, idx_s, extra = self._map(tracked.channels)
        w = np.array(tracked.weights, np.float32)
        lost = np.isnan(w[idx_t])
        w[idx_t] = np.where(lost, face[idx_s], w[idx_t] + np.where(self._residual[idx_s], residual[idx_s], 0.0))
        weights = np.concatenate([w, face[extra]])
        if tracked.head_rotation is not None and np.isfinite(tracked.head_rotation).all():
            from .geometry import quat_mul
            rot = quat_mul(tracked.head_rotation.astype(np.float64), rot)
        if tracked.head_translation is not None and np.isfinite(tracked.head_translation).all():
            trans = tracked.head_translation + trans
        return Frame(t, source=tracked.source, channels=names, weights=weights, head_rotation=rot,
                     head_translation=trans, audio_level=tracked.audio_level, t_sender=tracked.t_sender,
                     number=tracked.number)

    def _pose(self, add: np.ndarray):
        v = [float(add[i]) if i >= 0 else 0.0 for i in self._head]
        return euler_to_quat(v[0], v[1], v[2]), np.array(v[3:], np.float32)

    def _map(self, channels):
        hit = self._maps.get(channels)
        if hit is None:
            keys = [canonical(c) for c in channels]
            idx_t, idx_s = [], []
            for j, n in enumerate(self._face_names):
                if n in keys:
                    idx_t.append(keys.index(n))
                    idx_s.append(j)
            extra = np.array([j for j, n in enumerate(self._face_names) if n not in keys], np.int64)
            names = tuple(channels) + tuple(self._face_names[j] for j in extra)
            hit = self._maps[channels] = (names, np.array(idx_t, np.int64), np.array(idx_s, np.int64), extra)
        return hit


class VoiceOnlySource:
    """A tracker source that never delivers a frame (``--input audio``): the face comes from the voice.

    Has the parts of a live source the run command uses (``start``, ``stop``, ``latest``,
    ``counters``, ``address``, ``duration``).
    """

    address = ("voice", 0)

    def __init__(self, duration: float | None = None):
        self.duration = duration
        self.counters: dict = {}

    def start(self) -> None:
        pass

    def stop(self) -> None:
        pass

    def latest(self, t: float):
        return None, 0


def gesture_layer(path, inner=None, level=None, voice_only: bool = False, seed: int = 0, log=print) -> GestureLayer:
    """A :class:`GestureLayer` over ``inner`` from the gesture tables at ``path`` (the run command's ``--gestures``)."""
    db = load_gesture_db(path)
    synth = GestureSynth(db, seed=seed)
    fps = float(db.settings.get("fps", 30.0))
    log(f"gestures: {path} ({len(db['intensity'])} reference frames at {fps:g} fps, groups "
        f"{', '.join(synth.groups)}), {'voice only' if voice_only else 'added to the tracked face'}")
    return GestureLayer(synth, fps=fps, mode="voice" if voice_only else "add", level=level, inner=inner)
