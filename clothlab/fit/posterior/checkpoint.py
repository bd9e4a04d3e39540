"""Checkpoints of a posterior run: what fixes the chain (a fingerprint) and its state, saved atomically.

The checkpoint (``.npz``, written by :func:`clothlab.atomic.atomic_write_bytes` after every chunk of steps and
on KeyboardInterrupt) holds the chain, log-probabilities and the sampler's random state after the last
completed step, so a resumed run yields the same chain as an uninterrupted one.  A checkpoint of another target
distribution (:data:`TARGET_KEYS`) is replaced by a fresh run; one of the same target made with other sampler
settings is refused.
"""

from __future__ import annotations

import hashlib
import io
import json
import time
import zipfile
from dataclasses import dataclass, field
from dataclasses import fields as dataclass_fields
from pathlib import Path

import numpy as np

from clothlab.atomic import atomic_write_bytes
from clothlab.errors import InputError

CHECKPOINT_VERSION = 3  # 3: the walkers' start (Laplace approximation or ball) in the fingerprint


def _model_settings(model) -> dict:
    """What of the model (besides the parameters) changes the likelihood: the quadrature (rule, nodes) of the
    IM yarn integrals, the other models' scalar options (e.g. Kang's tile_nodes), and the weave geometry."""
    out = {"kind": type(model).__name__}
    q = model.quadrature
    if q is not None:
        out["quadrature"] = {"rule": str(q.rule), "nodes": int(q.nodes)}
    for key, value in sorted(vars(model).items()):
        if not key.startswith("_") and key != "quadrature" and (value is None or isinstance(value, bool | int |
                                                                                             float | str)):
            out[key] = value
    weave = model.weave
    if weave is not None:
        digest = hashlib.sha256(np.ascontiguousarray(weave.pattern).tobytes())
        digest.update(repr([getattr(weave, f.name) for f in dataclass_fields(weave)
                            if f.compare and f.name != "pattern"]).encode())
        out["weave"] = f"{weave.name}:{digest.hexdigest()[:16]}"
    return out


def _fingerprint(problem, like, walkers: int, seed: int, x_opt: np.ndarray, moves: str = "de-snooker", *,
                 start: str = "laplace") -> str:
    """What fixes the target distribution and the chain: a resumed run must match it exactly.

    Keys of the target (:data:`TARGET_KEYS`: data, model and its quadrature, free / fixed parameters, bounds,
    noise model, the optimum the walkers start from) and of the sampler (walkers, seed, moves, the walkers'
    start, version; a checkpoint without ``moves`` was made with the stretch move).  The optimum
    is recorded in unit coordinates rounded to 10 significant digits (a rerun of the same seeded fit reproduces
    it; a changed fit budget or start does not)."""
    m = problem.measurement
    digest = hashlib.sha256()
    for array in (problem.y, m.sigma, problem.wi, problem.wo):
        if array is not None:
            digest.update(np.ascontiguousarray(array, dtype=np.float64).tobytes())
    fixed = {k: v for k, v in sorted(problem.start.items()) if k not in problem.free}
    return json.dumps({"version": CHECKPOINT_VERSION, "model": _model_settings(problem.model), "free": like.names,
                       "lower": problem.lower.tolist(), "upper": problem.upper.tolist(), "fixed": fixed,
                       "noise": like.noise, "walkers": walkers, "seed": seed, "moves": moves, "start": start,
                       "data": digest.hexdigest(),
                       "optimum": [f"{float(v):.10g}" for v in np.asarray(x_opt, dtype=np.float64)]},
                      sort_keys=True)


TARGET_KEYS = frozenset({"model", "free", "lower", "upper", "fixed", "noise", "data", "optimum"})
"""Fingerprint keys that define the target distribution (or its starting point): a checkpoint differing in any
of them (or in the checkpoint version) belongs to another fit and is replaced by a fresh run, with a message; a
checkpoint of the same target differing only in the sampler settings (walkers, seed, moves) is refused, so a mistyped
option loses no chain."""


class _StaleCheckpoint(Exception):
    """The checkpoint was made for another target distribution (see TARGET_KEYS); ``diff`` names the keys."""

    def __init__(self, diff):
        super().__init__(", ".join(diff))
        self.diff = diff


@dataclass
class _ChainState:
    initial: np.ndarray  # (W, D) the starting ball
    chain: np.ndarray  # (n, W, D) unit coordinates
    log_prob: np.ndarray  # (n, W)
    coords: np.ndarray  # (W, D) last positions (the initial ones when n == 0)
    last_log_prob: np.ndarray  # (W,)
    random_state: tuple
    tau_history: dict = field(default_factory=dict)  # steps -> (D,) tau
    elapsed: float = 0.0  # sampling seconds of earlier sessions (resumed runs)
    started: float = field(default_factory=time.perf_counter)  # start of this session (perf_counter)

    @property
    def steps(self) -> int:
        return self.chain.shape[0]

    def session(self) -> float:
        """Seconds since this session started."""
        return time.perf_counter() - self.started


def _save_checkpoint(path: Path, fingerprint: str, st: _ChainState) -> None:
    """Write the chain state atomically (a reader sees the old or the new checkpoint, never a mix)."""
    name, keys, pos, has_gauss, cached = st.random_state
    steps_done = np.array(sorted(st.tau_history), dtype=np.int64)
    taus = np.array([st.tau_history[s] for s in steps_done]).reshape(len(steps_done), st.coords.shape[1])
    buf = io.BytesIO()
    np.savez(buf, fingerprint=np.array(fingerprint), initial=st.initial, chain=st.chain, log_prob=st.log_prob,
             coords=st.coords, last_log_prob=st.last_log_prob, rs_name=np.array(name), rs_keys=keys,
             rs_pos=np.array(pos), rs_has_gauss=np.array(has_gauss), rs_cached=np.array(cached),
             tau_steps=steps_done, tau_values=taus, elapsed=np.array(st.elapsed + st.session()))
    atomic_write_bytes(path, buf.getvalue())


_CHECKPOINT_KEYS = ("fingerprint", "initial", "chain", "log_prob", "coords", "last_log_prob", "rs_name", "rs_keys",
                    "rs_pos", "rs_has_gauss", "rs_cached", "tau_steps", "tau_values", "elapsed")


def _unreadable(path: Path, why) -> InputError:
    return InputError(f"posterior checkpoint is unreadable ({why}): an empty, truncated or foreign file; "
                      "delete it to start the posterior over", path=path)


def _load_checkpoint(path: Path, fingerprint: str) -> _ChainState:
    """The chain state of a checkpoint; InputError for an empty, truncated or malformed file (refused, so
    nothing is silently discarded), :class:`_StaleCheckpoint` for another target distribution."""
    try:
        if path.stat().st_size == 0:
            raise _unreadable(path, "the file is empty")
        with open(path, "rb") as handle, np.load(handle, allow_pickle=False) as z:
            missing = [key for key in _CHECKPOINT_KEYS if key not in z.files]
            if missing:
                raise _unreadable(path, f"missing {', '.join(missing)}")
            stored = str(z["fingerprint"])
            data = {key: z[key] for key in z.files}
        old = json.loads(stored)
        if not isinstance(old, dict):
            raise ValueError("the fingerprint is not a mapping")
    except InputError:
        raise
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
        raise _unreadable(path, exc) from None
    if stored != fingerprint:
        new = json.loads(fingerprint)
        diff = sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))
        if set(diff) & (TARGET_KEYS | {"version"}):
            raise _StaleCheckpoint(diff)
        raise InputError(f"posterior checkpoint was made with other settings (differs in: {', '.join(diff)}); "
                         "delete it to start over or restore the settings", path=path)
    tau = {int(s): v for s, v in zip(data["tau_steps"], data["tau_values"], strict=True)}
    rs = (str(data["rs_name"]), data["rs_keys"], int(data["rs_pos"]), int(data["rs_has_gauss"]),
          float(data["rs_cached"]))
    return _ChainState(data["initial"], data["chain"], data["log_prob"], data["coords"], data["last_log_prob"],
                       rs, tau, float(data["elapsed"]))
