"""Frame records streamed to columnar files, and exact statistics over spilled points.

A :class:`RecordStore` keeps the records of one scenario (``report.FrameRecord`` s, encoded
by ``report.records_to_batch``): a few in memory, the rest in Arrow IPC segment files (one
record batch each) in a spool folder, so a run's memory does not grow with its frames. A worker process spools into
the run's folder and the parent adopts its segments in order (no copy) and the records it holds in
memory (encoded).

A :class:`PointPool` pools float samples (error distances, σ) in order and gives the same
statistics as numpy over the whole array (``np.mean``, ``np.percentile``, ...), bit for bit,
while holding at most :data:`POOL_MEMORY_POINTS` of them in memory: beyond that they are
spilled to a file and the statistics are computed in passes over it (numpy's pairwise
summation replayed block by block; percentiles from the exact order statistics).
"""

from __future__ import annotations

import itertools
import math
import os
import shutil
import tempfile
import weakref
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Final, Iterable, Iterator, Sequence

import numpy as np

from cold_maps.evaluation.columns import to_numpy
from cold_maps.network.lane_strip import NDArrayFloat

if TYPE_CHECKING:
    import pyarrow as pa

FLUSH_RECORDS: Final[int] = 2048
"""Records a store holds in memory before it writes them as one segment."""
FLUSH_POINTS: Final[int] = 1 << 16
"""Error samples (8 bytes each) a store holds in memory before it writes a segment."""
POOL_MEMORY_POINTS: Final[int] = 1 << 20
"""Samples (8 bytes each) a :class:`PointPool` holds in memory before it spills to a file."""
READ_POINTS: Final[int] = 1 << 16
"""Samples a spilled pool reads at a time."""
SELECT_BINS: Final[int] = 1024
"""Value bins of one narrowing pass of the exact order-statistic search."""
PAIRWISE_BLOCK: Final[int] = 8
"""numpy's pairwise summation splits a sum at a multiple of this many elements..."""
PAIRWISE_LEAF: Final[int] = 128
"""... when it has more than this many (numpy's ``PW_BLOCKSIZE``)."""


_FILE_NUMBERS = itertools.count()
"""Numbers of the files this process makes (with its pid: unique in a shared folder)."""


class Spool:
    """A folder of segment files: a fresh temporary one (removed when the spool is closed or
    garbage-collected, or at exit) or a given one that belongs to someone else (a worker
    spools into its parent's).

    Fields: ``path`` the folder (made at the first segment).
    """

    def __init__(self, path: Path | None = None) -> None:
        self._path: Path | None = path
        self._finalizer: weakref.finalize | None = None

    @property
    def path(self) -> Path:
        """The folder (a fresh temporary one is made at the first call)."""
        if self._path is None:
            self._path = Path(tempfile.mkdtemp(prefix="cold-eval-records-"))
            self._finalizer = weakref.finalize(self, shutil.rmtree, self._path, True)
        return self._path

    def new_file(self, suffix: str) -> Path:
        """A new file name in the folder, unique across the processes that share it."""
        return self.path / f"{os.getpid()}-{next(_FILE_NUMBERS)}{suffix}"

    def close(self) -> None:
        """Removes the folder when this spool made it."""
        if self._finalizer is not None:
            self._finalizer()

    def __getstate__(self) -> dict[str, Any]:
        return {"path": self._path}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["path"])  # type: ignore[misc]


def list_values(column: pa.Array) -> tuple[NDArrayFloat, np.ndarray]:
    """(flat values, offsets ``(N + 1,)``) of a list<float64> column (a null list is empty)."""
    return to_numpy(column.values), to_numpy(column.offsets).astype(np.int64)


class RecordStore:
    """The records of one scenario, in order: segment files in a :class:`Spool` and the
    latest few in memory (module docstring). ``encode`` turns records into one record batch
    (each record's error samples in its list column ``errors_m``), ``decode`` a batch back
    into records (both module-level functions: a store is pickled with them); iterating
    yields the records.

    The records in memory are written as one segment past :data:`FLUSH_RECORDS` records or
    :data:`FLUSH_POINTS` samples, whether they were added one by one or came encoded from a
    pickled store (a worker's): the segments, and so the row groups of ``frames.parquet``,
    are the same for any number of workers."""

    def __init__(self, spool: Spool, encode: Callable[[Sequence[Any]], pa.RecordBatch],
                 decode: Callable[[pa.RecordBatch], Iterator[Any]]) -> None:
        self.spool = spool
        self.encode = encode
        self.decode = decode
        self.segments: list[Path] = []
        self.pending: list[Any] = []
        self.count = 0
        self._encoded: list[pa.RecordBatch] = []
        self._encoded_rows = 0
        self._pending_points = 0
        self._pending_batch: pa.RecordBatch | None = None

    @property
    def pending_rows(self) -> int:
        """Records held in memory: the encoded ones (a pickled store's), then :attr:`pending`."""
        return self._encoded_rows + len(self.pending)

    def add(self, record: Any) -> None:
        """Appends one record (written out with the pending ones past the flush limits)."""
        self.pending.append(record)
        self._pending_batch = None
        self.count += 1
        self._pending_points += len(record.errors_m)
        if self.pending_rows >= FLUSH_RECORDS or self._pending_points >= FLUSH_POINTS:
            self.flush()

    def _add_encoded(self, batch: pa.RecordBatch) -> None:
        """Appends encoded records, written out where adding them one by one would write them."""
        if self.pending:  # encoded first, so the records stay in order
            self._encoded.append(self.encode(self.pending))
            self._encoded_rows += len(self.pending)
            self.pending = []
        points = np.diff(list_values(batch.column("errors_m"))[1])
        start = 0
        while start < batch.num_rows:
            rows = self._encoded_rows + np.arange(1, batch.num_rows - start + 1)
            total = self._pending_points + np.cumsum(points[start:])
            full = np.flatnonzero((rows >= FLUSH_RECORDS) | (total >= FLUSH_POINTS))
            stop = start + int(full[0]) + 1 if full.size else batch.num_rows
            self._encoded.append(batch.slice(start, stop - start))
            self._encoded_rows += stop - start
            self._pending_points = int(total[stop - start - 1])
            self.count += stop - start
            self._pending_batch = None
            if full.size:
                self.flush()
            start = stop

    def _pending(self) -> pa.RecordBatch:
        """The records held in memory as one batch (kept until the next change)."""
        if self._pending_batch is None:
            import pyarrow as pa

            parts = [*self._encoded, *([self.encode(self.pending)] if self.pending else [])]
            self._pending_batch = parts[0] if len(parts) == 1 else pa.concat_batches(parts)
        return self._pending_batch

    def flush(self) -> None:
        """Writes the records held in memory as one segment."""
        if not self.pending_rows:
            return
        import pyarrow as pa

        batch = self._pending()
        path = self.spool.new_file(".arrow")
        with pa.OSFile(str(path), "wb") as sink, pa.ipc.new_file(sink, batch.schema) as writer:
            writer.write_batch(batch)
        self.segments.append(path)
        self.pending, self._encoded = [], []
        self._encoded_rows = self._pending_points = 0
        self._pending_batch = None

    def extend(self, later: RecordStore) -> None:
        """Appends the records of ``later``: its segments adopted as they are, the records it
        holds in memory added (a pickled store holds them encoded, see :meth:`__getstate__`)."""
        if later.segments:
            self.flush()
            self.segments.extend(later.segments)
            self.count += later.count - later.pending_rows
        for batch in later._encoded:
            self._add_encoded(batch)
        for record in later.pending:
            self.add(record)

    def batches(self, columns: Sequence[str] | None = None) -> Iterator[pa.RecordBatch]:
        """The records as batches of ``encode``'s schema (``columns`` only), in order."""
        import pyarrow as pa

        for path in self.segments:
            with pa.OSFile(str(path), "rb") as source:
                reader = pa.ipc.open_file(source)
                for index in range(reader.num_record_batches):
                    batch = reader.get_batch(index)
                    yield batch if columns is None else batch.select(list(columns))
        if self.pending_rows:
            batch = self._pending()
            yield batch if columns is None else batch.select(list(columns))

    def values(self, column: str) -> Iterator[Any]:
        """The Python values of one scalar column, in order."""
        for batch in self.batches((column,)):
            yield from batch.column(0).to_pylist()

    def __iter__(self) -> Iterator[Any]:
        for batch in self.batches():
            yield from self.decode(batch)

    def __len__(self) -> int:
        return self.count

    def __getstate__(self) -> dict[str, Any]:
        """The store with the records it holds in memory as one encoded batch: a worker's
        store travels to the parent as Arrow buffers, which pickle several times faster than
        the records."""
        return {"spool": self.spool, "encode": self.encode, "decode": self.decode, "segments": self.segments,
                "count": self.count, "encoded": [self._pending()] if self.pending_rows else [],
                "pending_points": self._pending_points}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__init__(state["spool"], state["encode"], state["decode"])  # type: ignore[misc]
        self.segments, self.count = state["segments"], state["count"]
        self._encoded, self._pending_points = state["encoded"], state["pending_points"]
        self._encoded_rows = sum(batch.num_rows for batch in self._encoded)


def pairwise_sum(read: Callable[[int, int], NDArrayFloat], start: int, count: int) -> float:
    """``np.sum`` of the ``count`` samples from ``start`` that ``read(start, count)`` returns,
    bit for bit: numpy's pairwise summation, split as numpy splits it, with the blocks of at
    most :data:`READ_POINTS` (or numpy's unsplit :data:`PAIRWISE_LEAF`) summed by numpy itself."""
    if count <= max(READ_POINTS, PAIRWISE_LEAF):
        return float(np.add.reduce(read(start, count))) if count else 0.0
    half = count // 2
    half -= half % PAIRWISE_BLOCK
    return pairwise_sum(read, start, half) + pairwise_sum(read, start + half, count - half)


def numpy_lerp(low: float, high: float, gamma: float) -> float:
    """numpy's linear interpolation between two order statistics (``np.percentile``'s
    ``_lerp``: from the nearer end)."""
    diff = high - low
    return high - diff * (1.0 - gamma) if gamma >= 0.5 else low + diff * gamma


class PointPool:
    """Float samples pooled in order (module docstring); ``spool`` takes the spill file, past
    ``limit`` samples (default :data:`POOL_MEMORY_POINTS`)."""

    def __init__(self, spool: Spool, limit: int | None = None) -> None:
        self._spool = spool
        self._limit = POOL_MEMORY_POINTS if limit is None else limit
        self._chunks: list[NDArrayFloat] = []
        self._file: Any = None
        self._path: Path | None = None
        self.size = 0

    def append(self, values: NDArrayFloat) -> None:
        """Appends samples (copied)."""
        values = np.ascontiguousarray(values, dtype=np.float64)
        if not values.size:
            return
        self.size += values.size
        if self._file is None and self.size <= self._limit:
            self._chunks.append(values.copy())
            return
        if self._file is None:
            self._path = self._spool.new_file(".f64")
            self._file = open(self._path, "wb+")  # noqa: SIM115 - closed by close()
            for chunk in self._chunks:
                chunk.tofile(self._file)
            self._chunks = []
        values.tofile(self._file)

    @property
    def spilled(self) -> bool:
        """Whether the samples are in a file (else all in memory)."""
        return self._file is not None

    def array(self) -> NDArrayFloat:
        """All samples (only while not :attr:`spilled`; do not change them): the chunks are
        joined once, not at every statistic."""
        assert self._file is None, "a spilled pool is read in blocks"
        if len(self._chunks) > 1:
            self._chunks = [np.concatenate(self._chunks)]
        return self._chunks[0] if self._chunks else np.empty(0)

    def read(self, start: int, count: int) -> NDArrayFloat:
        """``count`` samples from index ``start``."""
        if self._file is None:
            return self.array()[start:start + count]
        self._file.flush()
        self._file.seek(start * 8)
        return np.fromfile(self._file, dtype=np.float64, count=count)

    def blocks(self) -> Iterator[NDArrayFloat]:
        """The samples in blocks of at most :data:`READ_POINTS`, in order."""
        for start in range(0, self.size, READ_POINTS):
            yield self.read(start, min(READ_POINTS, self.size - start))

    def mean(self, transform: Callable[[NDArrayFloat], NDArrayFloat] | None = None) -> float:
        """``np.mean`` of the samples (of ``transform`` of them, element-wise), NaN when empty."""
        if not self.size:
            return math.nan
        if self._file is None:
            values = self.array()
            return float(np.mean(values if transform is None else transform(values)))
        read = self.read if transform is None else (lambda start, count: transform(self.read(start, count)))
        return float(np.float64(pairwise_sum(read, 0, self.size)) / self.size)

    def max(self) -> float:
        """The largest sample, NaN when empty."""
        if not self.size:
            return math.nan
        return float(max(block.max() for block in self.blocks()))

    def count(self, test: Callable[[NDArrayFloat, int], np.ndarray]) -> int:
        """How many samples pass ``test(block, start)`` (a boolean array per block)."""
        total, start = 0, 0
        for block in self.blocks():
            total += int(np.count_nonzero(test(block, start)))
            start += block.size
        return total

    def _window(self, low: float, high: float) -> tuple[int, float, float]:
        """(count, min, max) of the samples in ``[low, high]`` (min, max NaN when none)."""
        count, smallest, largest = 0, math.inf, -math.inf
        for block in self.blocks():
            chosen = block[(block >= low) & (block <= high)]
            if chosen.size:
                count += chosen.size
                smallest, largest = min(smallest, float(chosen.min())), max(largest, float(chosen.max()))
        return count, smallest, largest

    def order_statistic(self, rank: int) -> float:
        """The sample at ``rank`` (0-based) in sorted order, exact: passes over the samples
        narrow a value window ``[low, high]`` that holds it (``below`` samples lie under it)
        until the window's samples fit in memory."""
        low, high, below = -math.inf, math.inf, 0
        while True:
            inside, smallest, largest = self._window(low, high)
            if inside <= self._limit or smallest == largest:
                if smallest == largest:
                    return smallest
                window = np.concatenate([block[(block >= low) & (block <= high)] for block in self.blocks()])
                return float(np.partition(window, rank - below)[rank - below])
            edges = np.linspace(smallest, largest, SELECT_BINS + 1)
            counts = np.zeros(SELECT_BINS, dtype=np.int64)
            for block in self.blocks():  # bin j holds edges[j] <= v < edges[j + 1], the last one v <= largest
                chosen = block[(block >= smallest) & (block <= largest)]
                counts += np.bincount(np.minimum(np.searchsorted(edges, chosen, side="right") - 1, SELECT_BINS - 1),
                                      minlength=SELECT_BINS)
            cumulative = below + np.cumsum(counts)
            j = int(np.searchsorted(cumulative, rank, side="right"))
            top = largest if j == SELECT_BINS - 1 else float(np.nextafter(edges[j + 1], -math.inf))
            if float(edges[j]) == smallest and top == largest:  # the values lie within a few ulps
                return self._ranked_exactly(smallest, largest, rank - below)
            low, high, below = float(edges[j]), top, int(cumulative[j - 1]) if j else below

    def _ranked_exactly(self, low: float, high: float, rank: int) -> float:
        """The sample at ``rank`` among those in ``[low, high]``, counted by distinct value."""
        counts: dict[float, int] = {}
        for block in self.blocks():
            values, found = np.unique(block[(block >= low) & (block <= high)], return_counts=True)
            for value, n in zip(values.tolist(), found.tolist()):
                counts[value] = counts.get(value, 0) + n
        seen = 0
        for value in sorted(counts):
            seen += counts[value]
            if seen > rank:
                return value
        raise AssertionError("rank outside the window")

    def next_order_statistic(self, value: float, rank: int) -> float:
        """The sample at ``rank + 1`` given ``value``, the one at ``rank``."""
        if self.count(lambda block, _: block <= value) > rank + 1:
            return value
        return min(float(b[b > value].min()) for b in self.blocks() if (b > value).any())

    def percentile(self, percent: float) -> float:
        """``np.percentile(samples, percent)`` (linear), NaN when empty."""
        if not self.size:
            return math.nan
        if self._file is None:
            return float(np.percentile(self.array(), percent))
        quantile = np.true_divide(percent, 100)
        virtual = (self.size - 1) * quantile
        if virtual >= self.size - 1:
            return self.order_statistic(self.size - 1)
        previous = math.floor(virtual)
        gamma = float(virtual - np.float64(previous))
        low = self.order_statistic(previous)
        return numpy_lerp(low, self.next_order_statistic(low, previous), gamma)

    def partition_percentile(self, percent: float) -> float:
        """``gt_matching.metrics._percentile`` of the samples (its formula by partial sorting), NaN when empty."""
        if not self.size:
            return math.nan
        position = percent / 100.0 * (self.size - 1)
        below = int(np.floor(position))
        above = min(below + 1, self.size - 1)
        if self._file is None:
            low, high = np.partition(self.array(), (below, above))[[below, above]]
        else:
            low = np.float64(self.order_statistic(below))
            high = low if above == below else np.float64(self.next_order_statistic(float(low), below))
        return float(low + (high - low) * (position - below))

    def close(self) -> None:
        """Drops the samples and the spill file."""
        if self._file is not None:
            self._file.close()
            assert self._path is not None
            self._path.unlink(missing_ok=True)
        self._file, self._chunks, self.size = None, [], 0


def pools(spool: Spool, names: Iterable[str]) -> dict[str, PointPool]:
    """One empty :class:`PointPool` per name."""
    return {name: PointPool(spool) for name in names}
