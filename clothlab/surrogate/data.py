"""Training data: footprint queries sampled as Chen, Wang & Wang 2024, sec. 5.1 / Table 2, labelled by a
label source (:mod:`.labels`), stored chunk by chunk as ``.npy`` files and read back memory-mapped.

Per material, the tile is cut into a ``centres`` x ``centres`` grid (8 x 8 in the paper) and one footprint
centre is drawn uniformly in each cell; each centre gets ``sizes`` footprint sizes stratified uniformly in
each range of :data:`SIZE_RANGES` ((0, 1) and (1, 5) tiles, 10 each in the paper; sizes below
:data:`MIN_SIZE` are raised to it); each footprint gets ``pairs`` direction pairs drawn from the stratified
``directions`` x ``directions`` grid over (x, y) in (-1, 1)^2 of both wi and wo (8 x 8), z = sqrt(1 - x^2 -
y^2), reflection only (z >= :data:`MIN_Z` for both).  A fixed, seeded subset (``heldout_pairs``) of the
(wi cell, wo cell) pairs is never trained on: the held-out direction pairs.

A *chunk* is one (material, centre cell): ``sizes x len(SIZE_RANGES) x pairs`` rows, generated from its own
seed ``(seed, material, cell)`` alone, so chunks are independent tasks (any order, any machine) and a run
resumes by generating only the chunks whose file is missing.  Every row has its own direction pair: with
the same label budget this generalises to held-out pairs far better than a few pairs meeting every
footprint (measured: relative RMSE 0.04-0.16 against 0.19-0.34 at >= 0.12 tile, docs/notes/neural-log.md), but a
labeller that tabulates per direction pair (summed-area tables) then builds one table per row.
``mirror_share`` (not in the paper): that share of each chunk's rows gets wo drawn near the mirror direction
of wi instead (its (x, y) within :data:`MIRROR_RADIUS` of (-wi_x, -wi_y)), where the yarn highlights are:
near-mirror pairs with min(cos theta) < 0.4 are 1.3 % of uniform pairs but carry 38-42 % of sum f^2 of
single texture points for cotton twill and wool gabardine (docs/neural.md, "Retrains").  Held-out flags follow
the new cells; :func:`heldout_queries` keeps the uniform pairs.
Row columns: :data:`COLUMNS` then the label source's components.
"""

from __future__ import annotations

import hashlib
import io
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from clothlab.atomic import atomic_write_bytes
from clothlab.progress import Progress, get_logger

LOG = get_logger("surrogate.data")
SIZE_RANGES = ((0.0, 1.0), (1.0, 5.0))
MIN_SIZE = 0.01  # tiles
SMALL_RANGE = (0.01, 0.12)  # tiles: the range of DataSpec.small_sizes
MIN_Z = 0.05
MIRROR_RADIUS = 0.3  # DataSpec.mirror_share: wo's (x, y) within this distance of the mirror direction's
COLUMNS = ("material", "u", "v", "size", "wi_x", "wi_y", "wi_z", "wo_x", "wo_y", "wo_z", "heldout_pair")


@dataclass(frozen=True)
class DataSpec:
    """How queries are sampled (module docstring); ``heldout_pairs``: fraction of direction-cell pairs."""

    centres: int = 8
    sizes: int = 10
    directions: int = 8
    pairs: int = 64
    heldout_pairs: float = 0.1
    seed: int = 0
    small_sizes: int = 0
    row_centres: bool = False
    mirror_share: float = 0.0

    def __post_init__(self):
        if not 0.0 <= self.mirror_share < 1.0:
            raise ValueError(f"mirror_share must be in [0, 1), got {self.mirror_share}")

    def sizes_per_centre(self) -> int:
        return self.sizes * len(SIZE_RANGES) + self.small_sizes

    def rows_per_chunk(self) -> int:
        return self.sizes_per_centre() * self.pairs

    def chunks_per_material(self) -> int:
        return self.centres * self.centres

    def to_dict(self) -> dict:
        """The fields; ``mirror_share`` only when set (specs written before it existed compare equal)."""
        out = asdict(self)
        if not self.mirror_share:
            del out["mirror_share"]
        return out


def heldout_cells(spec: DataSpec) -> np.ndarray:
    """(D^2, D^2) bool: the (wi cell, wo cell) pairs held out (seeded by ``spec.seed`` only)."""
    d2 = spec.directions ** 2
    return np.random.default_rng([spec.seed, 7919]).random((d2, d2)) < spec.heldout_pairs


def direction_cells(w: np.ndarray, directions: int) -> np.ndarray:
    """(N,) index of the cell of the ``directions`` x ``directions`` grid over (x, y) in (-1, 1)^2 that holds
    each direction of ``w`` (N, 3): the cell index of :func:`_stratified_directions` (x along the row)."""
    ij = np.clip(np.floor((np.asarray(w)[:, :2] + 1.0) * (0.5 * directions)).astype(np.int64), 0, directions - 1)
    return ij[:, 0] + directions * ij[:, 1]


def swap_trained(rows: np.ndarray, spec: DataSpec) -> np.ndarray:
    """(N,) bool: the rows whose swapped directions (wi <-> wo) fall in a trained (wi cell, wo cell) pair
    (not in :func:`heldout_cells`), so that training on the swapped row never sees a held-out pair."""
    held = heldout_cells(spec)
    return ~held[direction_cells(np.asarray(rows)[:, 7:10], spec.directions),
                 direction_cells(np.asarray(rows)[:, 4:7], spec.directions)]


def _stratified_directions(rng: np.random.Generator, d: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """n directions with (x, y) jittered in random cells of the d x d grid over (-1, 1)^2, z >= MIN_Z."""
    out, cells = np.empty((0, 3)), np.empty(0, dtype=np.int64)
    while len(out) < n:
        cell = rng.integers(0, d * d, 2 * n)
        xy = -1.0 + 2.0 * (np.stack([cell % d, cell // d], axis=1) + rng.random((2 * n, 2))) / d
        z2 = 1.0 - np.sum(xy * xy, axis=1)
        ok = z2 >= MIN_Z ** 2
        out = np.concatenate([out, np.column_stack([xy[ok], np.sqrt(z2[ok])])])
        cells = np.concatenate([cells, cell[ok]])
    return out[:n], cells[:n]


def _mirror_directions(rng: np.random.Generator, wi: np.ndarray) -> np.ndarray:
    """(n, 3) directions wo whose (x, y) is uniform in the disc of radius :data:`MIRROR_RADIUS` around the
    mirror direction's (-wi_x, -wi_y), z >= :data:`MIN_Z` (redrawn until it is)."""
    out = np.empty_like(wi)
    todo = np.arange(len(wi))
    while todo.size:
        r, phi = MIRROR_RADIUS * np.sqrt(rng.random(todo.size)), 2.0 * np.pi * rng.random(todo.size)
        xy = -wi[todo, :2] + np.column_stack([r * np.cos(phi), r * np.sin(phi)])
        z2 = 1.0 - np.sum(xy * xy, axis=1)
        ok = z2 >= MIN_Z ** 2
        out[todo[ok]] = np.column_stack([xy[ok], np.sqrt(z2[ok])])
        todo = todo[~ok]
    return out


def chunk_queries(spec: DataSpec, material: int, cell: int) -> np.ndarray:
    """The query columns (rows, len(COLUMNS)) of one chunk (labels not yet attached)."""
    rng = np.random.default_rng([spec.seed, material, cell])
    c = spec.centres
    centre = (np.array([cell % c, cell // c]) + rng.random(2)) / c
    sizes = np.concatenate([lo + (hi - lo) * (np.arange(spec.sizes) + rng.random(spec.sizes)) / spec.sizes
                            for lo, hi in SIZE_RANGES])
    if spec.small_sizes:  # extra small footprints, log-stratified in SMALL_RANGE (beyond Table 2)
        lo, hi = np.log(SMALL_RANGE)
        strata = (np.arange(spec.small_sizes) + rng.random(spec.small_sizes)) / spec.small_sizes
        sizes = np.concatenate([sizes, np.exp(lo + (hi - lo) * strata)])
    sizes = np.maximum(sizes, MIN_SIZE)
    n = spec.rows_per_chunk()
    heldout = heldout_cells(spec)
    wi, cell_i = _stratified_directions(rng, spec.directions, n)
    wo, cell_o = _stratified_directions(rng, spec.directions, n)
    rows = np.empty((n, len(COLUMNS)))
    rows[:, 0] = material
    rows[:, 1:3] = centre
    rows[:, 3] = np.repeat(sizes, spec.pairs)
    rows[:, 4:7], rows[:, 7:10] = wi, wo
    rows[:, 10] = heldout[cell_i, cell_o]
    if spec.row_centres:  # every row its own centre in the chunk's cell (Table 2 has one per cell)
        rows[:, 1:3] = (np.array([cell % c, cell // c]) + rng.random((n, 2))) / c
    if spec.mirror_share:  # a seeded share of the rows gets wo near wi's mirror direction (the highlights)
        pick = rng.permutation(n)[:int(round(spec.mirror_share * n))]
        rows[pick, 7:10] = _mirror_directions(rng, rows[pick, 4:7])
        rows[pick, 10] = heldout[cell_i[pick], direction_cells(rows[pick, 7:10], spec.directions)]
    return rows


def heldout_queries(spec: DataSpec, n: int, seed: int = 0, sizes: tuple[float, float] = (MIN_SIZE, 5.0),
                    material: int = 0) -> np.ndarray:
    """``n`` evaluation queries (rows of :data:`COLUMNS`), each with its own direction pair from the held-out
    cells of ``spec``, a uniform centre and a size drawn as Table 2 (a range of :data:`SIZE_RANGES`, then
    uniform in it) and kept within ``sizes`` (tiles)."""
    rng = np.random.default_rng([spec.seed, seed, 104729])
    held = heldout_cells(spec)
    rows = np.empty((0, len(COLUMNS)))
    while len(rows) < n:
        m = 8 * n
        wi, cell_i = _stratified_directions(rng, spec.directions, m)
        wo, cell_o = _stratified_directions(rng, spec.directions, m)
        lo_hi = np.array(SIZE_RANGES)[rng.integers(0, len(SIZE_RANGES), m)]
        size = np.maximum(lo_hi[:, 0] + (lo_hi[:, 1] - lo_hi[:, 0]) * rng.random(m), MIN_SIZE)
        keep = held[cell_i, cell_o] & (size >= sizes[0]) & (size < sizes[1])
        block = np.column_stack([np.full(m, material), rng.random((m, 2)), size, wi, wo, np.ones(m)])[keep]
        rows = np.concatenate([rows, block])
    return rows[:n]


def chunk_path(directory: Path, material: int, cell: int) -> Path:
    return Path(directory) / f"chunk-{material:04d}-{cell:03d}.npy"


def generate_chunk(spec: DataSpec, labels, material: int, cell: int) -> np.ndarray:
    """Queries and labels (rows, len(COLUMNS) + C) of one chunk; ``labels``: the material's label source."""
    q = chunk_queries(spec, material, cell)
    y = labels(q[:, 4:7], q[:, 7:10], q[:, 1:3], q[:, 3])
    return np.concatenate([q, y], axis=1)


def _label_chunk(shared, item) -> bytes:
    """One chunk as .npy bytes (a task: ``shared`` = (spec, label sources), ``item`` = (material, cell);
    seeded, so where it runs is irrelevant)."""
    spec, label_sources = shared
    m, c = item
    buffer = io.BytesIO()
    np.save(buffer, generate_chunk(spec, label_sources[m], m, c), allow_pickle=False)
    return buffer.getvalue()


def generate(directory, spec: DataSpec, label_sources, *, stop=None, runner=None) -> int:
    """Write every missing chunk of every material (``label_sources[m]`` labels material m) into
    ``directory``; returns the number of chunks written.  ``stop()`` returning True ends early (a budget);
    the chunks written so far stay, and a later call resumes.  ``runner`` (:class:`clothlab.parallel.Runner`,
    e.g. Dask workers): the chunks as tasks, in rounds of a few per worker with ``stop`` checked between
    rounds; every chunk is seeded by (seed, material, cell), so the files are identical to the in-process ones."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    # cell-major order: a run stopped by its budget has labelled every material alike
    todo = [(m, c) for c in range(spec.chunks_per_material()) for m in range(len(label_sources))
            if not chunk_path(directory, m, c).exists()]
    written = 0
    if runner is not None:
        from clothlab.parallel.runner import raise_failures

        shared = runner.share((spec, label_sources))
        step = max(1, 4 * runner.workers)
        for start in range(0, len(todo), step):
            if stop is not None and stop():
                break
            items = todo[start:start + step]
            blocks = raise_failures(runner.map(_label_chunk, items, shared=shared, desc="labelling chunks",
                                               names=[f"chunk {m}/{c}" for m, c in items]), "label chunks")
            for (m, c), data in zip(items, blocks, strict=True):
                atomic_write_bytes(chunk_path(directory, m, c), data)
                written += 1
        return written
    with Progress(len(todo), "labelling footprint queries", unit="chunk") as bar:
        for m, c in todo:
            if stop is not None and stop():
                break
            atomic_write_bytes(chunk_path(directory, m, c), _label_chunk((spec, label_sources), (m, c)))
            written += 1
            bar.update(1)
    return written


def assemble(directory, spec: DataSpec, n_materials: int, n_components: int) -> tuple[np.ndarray, str]:
    """All chunks of ``directory`` as one memory-mapped array (``data.npy`` beside them) and its sha256.

    Missing chunks are skipped (a partial data set trains too).  Rebuilt when the chunk set changed."""
    directory = Path(directory)
    paths = [chunk_path(directory, m, c) for m in range(n_materials) for c in range(spec.chunks_per_material())]
    paths = [p for p in paths if p.exists()]
    if not paths:
        raise FileNotFoundError(f"no data chunks in {directory}")
    manifest = directory / "data.json"
    target = directory / "data.npy"
    names = [p.name for p in paths]
    if target.exists() and manifest.exists():
        saved = json.loads(manifest.read_text(encoding="utf-8"))
        if saved.get("chunks") == names and saved.get("spec") == spec.to_dict():
            return np.load(target, mmap_mode="r", allow_pickle=False), saved["sha256"]
    width = len(COLUMNS) + n_components
    rows = spec.rows_per_chunk()
    tmp = directory / ".data.npy.tmp"
    out = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.float64, shape=(rows * len(paths), width))
    digest = hashlib.sha256()
    for i, path in enumerate(paths):
        block = np.load(path, allow_pickle=False)
        out[i * rows:(i + 1) * rows] = block
        digest.update(block.tobytes())
    out.flush()
    del out
    tmp.replace(target)
    sha = digest.hexdigest()
    atomic_write_bytes(manifest, json.dumps({"chunks": names, "spec": spec.to_dict(), "sha256": sha}).encode())
    return np.load(target, mmap_mode="r", allow_pickle=False), sha
