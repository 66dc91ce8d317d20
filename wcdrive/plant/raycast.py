"""The lidar's fast ray cast: ``csrc/raycast.c`` walking a uniform grid of cells over a
world's segments and circles, giving the distances of ``World.cast_exact`` (the numpy
reference) bit for bit, a few hundred times faster on a ROS map's outline. A lidar's
turn casts its rays through a fan instead (``RayGrid.fan_bins``): the items listed by
the direction in which the turn's rays can meet them, nearest first, so a ray tests
one or two; the same figures as the walk, about twice as fast on the map's outline.

The one exception is where the reference's own figure is rounding noise: a ray within
an ulp of parallel to a segment whose line runs through the ray's origin gets t = 0
and a u that says nothing, and the reference may report a hit at the origin though the
segment is metres away; the C cast tests only the items near the ray's path and meets
what lies along it.

    grid = RayGrid.build(world.segments, world.circles)    # None without the C helper
    grid.cast(ox, oy, dx, dy, max_range)                    # (K,) metres, inf for none
    grid.scan(turn, t0, knots, noise)                       # a lidar's turn (wcdrive.plant.lidar)
    job = ScanJob(grid, turn, t0, noise=noise, motion=(start, log))
    with ScanPipe() as pipe:                                # turns made on a thread of its own
        pipe.submit(job)
        ...                                                 # the simulation runs on meanwhile
        pipe.wait(job)
        job.ranges, job.q2

``World.cast`` builds its grid on its first cast and uses it from then on; the
geometry's arrays are copied into the grid, so a world's arrays changed after its first
cast are not seen.
"""

from __future__ import annotations

import ctypes
import math
from pathlib import Path

import numpy as np

from wcdrive._util.native import BuildError, library, record
from wcdrive.plant.struct_layout import check_layout

Knots = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]

_SOURCE = Path(__file__).resolve().parent / "csrc" / "raycast.c"
_lib: ctypes.CDLL | bool | None = None
_draws: bool | None = None
_P = ctypes.c_void_p
_I = ctypes.c_int32
_D = ctypes.c_double

#: The grid's cell edge, as a multiple of the side of a square holding one item on
#: average (the geometry's bounding box over the number of items).
CELL_FACTOR = 1.0
#: Cells along a side at most.
MAX_CELLS = 2048
#: A turn's fan: its direction bins (0: each of its rays walks the grid instead).
FAN_BINS = 512
#: A fan's bins at most.
MAX_FAN_BINS = 1 << 16


class GridStruct(ctypes.Structure):
    """``rc_grid`` of raycast.c."""

    _fields_ = [("seg", _P), ("n_seg", _I), ("circ", _P), ("n_circ", _I),
                ("minx", _D), ("miny", _D), ("cs", _D), ("inv_cs", _D), ("nx", _I), ("ny", _I),
                ("eps", _D), ("start", _P), ("items", _P), ("rec", _P), ("seg_end", _P), ("item_rec", _P),
                ("fan_bins", _I), ("scale", _D)]


class TurnStruct(ctypes.Structure):
    """``rc_lidar`` of raycast.c."""

    _fields_ = [("samples", _I), ("offset", _P), ("device", _P), ("first_bin", _P), ("beams", _I),
                ("multiple", _I), ("mount_x", _D), ("mount_y", _D), ("sigma", _D), ("device_min", _D),
                ("range_max", _D), ("intensity", ctypes.c_float), ("reverse", _I)]


class JobStruct(ctypes.Structure):
    """``rc_job`` of raycast.c."""


JobStruct._fields_ = [("grid", _P), ("lidar", _P), ("t0", _D), ("n", _I), ("kt", _P), ("kx", _P), ("ky", _P),
                      ("kh", _P), ("log", _P), ("log_rows", _I), ("log_stride", _I), ("start_x", _D),
                      ("start_y", _D), ("start_h", _D), ("noise", _P), ("q2", _P), ("ranges", _P),
                      ("intensities", _P), ("beam_time", _P), ("state", _I), ("next_chunk", _I),
                      ("chunks_left", _I), ("next", ctypes.POINTER(JobStruct)), ("rays", _P), ("bitgen", _P),
                      ("draws", _P), ("log_t0", _D)]


class Turn:
    """What ``RayGrid.scan`` needs of a lidar and its driver: ``samples`` a turn taken at
    ``sample_hz``, sample j along ``device[j]`` (the unit vector in the chair's frame)
    from ``mount`` (x, y on the chair), binned from ``first_bin[j]`` into ``multiple``
    of ``beams`` bins (published last first with ``reverse``); ranges with ``sigma`` of
    noise, kept from ``device_min`` to ``range_max``, read with ``intensity``."""

    def __init__(self, sample_hz: float, device: np.ndarray, first_bin: np.ndarray, beams: int, multiple: int,
                 mount: tuple[float, float], sigma: float, device_min: float, range_max: float,
                 intensity: float, reverse: bool) -> None:
        self.device = np.ascontiguousarray(device, dtype=float).reshape(-1, 2).copy()
        self.first_bin = np.ascontiguousarray(first_bin, dtype=np.int32).copy()
        if len(self.first_bin) != len(self.device):
            raise ValueError("one first bin a sample")
        if beams < 1 or multiple < 1:
            raise ValueError("a turn has one beam at least, each sample one bin at least")
        if not 0 < range_max * 4000 < 2**31:
            raise ValueError(f"range_max {range_max} m: quarter millimetres must fit an int32")
        self.samples, self.beams = len(self.device), beams
        #: each sample's time in the turn (``j / sample_hz``, as numpy divides)
        self.offset = np.arange(self.samples) / sample_hz
        self.struct = TurnStruct(self.samples, _address(self.offset), _address(self.device),
                                 _address(self.first_bin), beams, multiple, mount[0], mount[1], sigma,
                                 device_min, range_max, intensity, int(reverse))


def load_raycast() -> ctypes.CDLL | None:
    """The C ray cast: the one the install built, else compiled on first use; None when
    neither can be had (``World.cast`` then runs the numpy cast). Raises
    ``wcdrive.plant.struct_layout.StructLayoutError`` when ``GridStruct``, ``TurnStruct``
    or ``JobStruct`` does not lay its C struct out as the compiler did."""
    global _lib
    if _lib is None:
        try:
            libs: tuple[str, ...] = ("-lm", "-lpthread")
            flags: tuple[str, ...] = ("-O2", "-ffp-contract=off")
            npyrandom = numpy_random()
            if npyrandom is not None:
                libs, flags = (str(npyrandom[1]), *libs), (*flags, "-DWC_NPYRANDOM", f"-I{npyrandom[0]}")
            lib, how = library("wcdrive.plant._raycast", _SOURCE, "raycast", libs, flags)
            check_layout(GridStruct, lib, "rc_grid_layout")
            check_layout(TurnStruct, lib, "rc_lidar_layout")
            check_layout(JobStruct, lib, "rc_job_layout")
            grid = ctypes.POINTER(GridStruct)
            lib.rc_count.argtypes = [grid, _P]
            lib.rc_count.restype = None
            lib.rc_fill.argtypes = [grid, _P]
            lib.rc_fill.restype = None
            lib.rc_cast.argtypes = [grid, _I, _P, _P, _P, _P, _D, _P]
            lib.rc_cast.restype = None
            lib.rc_integrate.argtypes = [_D, _D, _D, _D, _I, _P, _I, _P, _P, _P, _P]
            lib.rc_integrate.restype = None
            job = ctypes.POINTER(JobStruct)
            lib.rc_run.argtypes = [job]
            lib.rc_run.restype = None
            lib.rc_pipe_open.argtypes = []
            lib.rc_pipe_open.restype = _P
            for name in ("rc_pipe_submit", "rc_pipe_wait"):
                getattr(lib, name).argtypes = [_P, job]
                getattr(lib, name).restype = None
            lib.rc_pipe_close.argtypes = [_P]
            lib.rc_pipe_close.restype = None
            lib.rc_draws.argtypes = []
            lib.rc_draws.restype = _I
            _lib = lib
            record("ray cast", how)
        except (BuildError, OSError) as exc:            # OSError: no writable cache
            record("ray cast", f"Python ({exc})".splitlines()[0])
            _lib = False
    return _lib if isinstance(_lib, ctypes.CDLL) else None


def numpy_random() -> tuple[Path, Path] | None:
    """numpy's C headers and its ``libnpyrandom.a`` (its generators' C code, which the C
    scan links to draw a turn's noise as ``Generator.standard_normal`` does), None
    where this numpy ships no such library."""
    include = Path(np.get_include())
    lib = Path(np.__file__).parent / "random" / "lib" / "libnpyrandom.a"
    if (include / "numpy" / "random" / "bitgen.h").exists() and lib.exists():
        return include, lib
    return None


def draws_in_c() -> bool:
    """Whether the C scan draws a turn's noise itself (``ScanJob``'s ``draw``)."""
    global _draws
    if _draws is None:
        lib = load_raycast()
        _draws = lib is not None and bool(lib.rc_draws())
    return _draws


def _address(a: np.ndarray) -> int:
    return int(a.ctypes.data)


class RayGrid:
    """A uniform grid over fixed segments (N, 4) and circles (M, 3), and the C cast
    through it. Build it with ``build``."""

    def __init__(self, lib: ctypes.CDLL, segments: np.ndarray, circles: np.ndarray,
                 cell_factor: float = CELL_FACTOR, fan_bins: int | None = None) -> None:
        self._lib = lib
        self.segments = np.ascontiguousarray(segments, dtype=float).reshape(-1, 4).copy()
        self.circles = np.ascontiguousarray(circles, dtype=float).reshape(-1, 3).copy()
        seg, circ = self.segments, self.circles
        r = circ[:, 2:]
        lo = np.concatenate((seg[:, 0:2], seg[:, 2:4], circ[:, :2] - r)).min(axis=0, initial=np.inf)
        hi = np.concatenate((seg[:, 0:2], seg[:, 2:4], circ[:, :2] + r)).max(axis=0, initial=-np.inf)
        n = len(seg) + len(circ)
        if n == 0 or not (np.isfinite(lo).all() and np.isfinite(hi).all()):
            raise ValueError("a ray grid needs finite geometry, one segment or circle at least")
        scale = max(1.0, float(np.abs(np.concatenate((lo, hi))).max()))
        #: how near an item comes to a cell to be binned in it: far above the rounding
        #: of the walk's positions (about 1e-16 of the coordinates)
        self.eps = 1e-7 * scale
        w, h = float(hi[0] - lo[0]), float(hi[1] - lo[1])
        size = max(w, h, 1e-6)
        cs = cell_factor * math.sqrt(max(w, size / 64) * max(h, size / 64) / n)
        # at most MAX_CELLS a side, the padding (eps, large for a world far out) included,
        # and cells no smaller than the padding (else each would hold every item near it)
        cs = max(cs, (size + 4 * self.eps) / (MAX_CELLS - 2), 4 * self.eps, 1e-6)
        # cell edges off the round figures a map's walls lie on
        pad = 0.309 * cs + self.eps
        nx = math.floor((w + 2 * pad) / cs) + 1
        ny = math.floor((h + 2 * pad) / cs) + 1
        #: rows and columns of cells, the cells' edge (m), the grid's lower left corner
        self.shape = (ny, nx)
        self.cell = cs
        self.corner = (float(lo[0]) - pad, float(lo[1]) - pad)
        self._start = np.zeros(nx * ny + 1, dtype=np.int32)
        self._items = np.zeros(0, dtype=np.int32)
        self._struct = GridStruct(_address(seg), len(seg), _address(circ), len(circ),
                                  *self.corner, cs, 1.0 / cs, nx, ny, self.eps,
                                  _address(self._start), 0, None, None, None, 0, scale)
        ref = ctypes.byref(self._struct)
        counts = np.zeros(nx * ny, dtype=np.int32)
        lib.rc_count(ref, _address(counts))
        np.cumsum(counts, out=self._start[1:])
        self._items = np.zeros(int(self._start[-1]), dtype=np.int32)
        self._struct.items = _address(self._items) if len(self._items) else None
        cursor = self._start[:-1].copy()          # held here while C writes through it
        lib.rc_fill(ref, _address(cursor))
        # each cell's items as records for the cast: segments x0, y0, x1 - x0, y1 - y0 (the
        # reference's differences), circles x, y, r, 0
        items = self._items
        is_seg = items < len(seg)
        self._rec = np.zeros((max(len(items), 1), 4))
        records = np.column_stack((seg[:, 0:2], seg[:, 2:4] - seg[:, 0:2]))
        self._rec[:len(items)][is_seg] = records[items[is_seg]]
        self._rec[:len(items)][~is_seg, :3] = circ[items[~is_seg] - len(seg)]
        segs_before = np.concatenate(([0], np.cumsum(is_seg))).astype(np.int32)
        self._seg_end = (self._start[:-1] + segs_before[self._start[1:]] - segs_before[self._start[:-1]]
                         ).astype(np.int32)
        self._struct.rec, self._struct.seg_end = _address(self._rec), _address(self._seg_end)
        # the items' records in the items' order, for a turn's fan
        self._item_rec = np.zeros((n, 4))
        self._item_rec[:len(seg)] = records
        self._item_rec[len(seg):, :3] = circ
        self._struct.item_rec = _address(self._item_rec)
        self.fan_bins = FAN_BINS if fan_bins is None else fan_bins

    @property
    def fan_bins(self) -> int:
        """A turn's direction bins: each ray tests only the items its bin lists, in
        rising order of their least distance from the turn's origins (0: each ray walks
        the grid instead; the figures are the same). A turn of fewer samples than twice
        the world's items walks the grid (the fan's cost grows with the world's items:
        on a large map the walk is the faster), as does a ray whose direction is not a
        unit vector."""
        return int(self._struct.fan_bins)

    @fan_bins.setter
    def fan_bins(self, bins: int) -> None:
        if not 0 <= bins <= MAX_FAN_BINS:
            raise ValueError(f"fan bins: 0 to {MAX_FAN_BINS}, not {bins}")
        self._struct.fan_bins = bins

    @classmethod
    def build(cls, segments: np.ndarray, circles: np.ndarray, cell_factor: float = CELL_FACTOR,
              fan_bins: int | None = None) -> RayGrid | None:
        """The grid over that geometry; None without the C helper or without geometry."""
        lib = load_raycast()
        if lib is None or len(segments) + len(circles) == 0:
            return None
        return cls(lib, segments, circles, cell_factor, fan_bins)

    def cast(self, ox: np.ndarray, oy: np.ndarray, dx: np.ndarray, dy: np.ndarray,
             max_range: float = math.inf) -> np.ndarray:
        """For each ray from (ox, oy) along the unit vector (dx, dy), all (K,): the
        distance to the first segment or circle it meets within ``max_range``, else inf
        (``World.cast_exact``'s figures)."""
        arrays = [np.ascontiguousarray(a, dtype=float) for a in (ox, oy, dx, dy)]
        k = len(arrays[0])
        out = np.empty(k)
        if k:
            self._lib.rc_cast(ctypes.byref(self._struct), k, *(_address(a) for a in arrays), float(max_range),
                              _address(out))
        return out

    def scan(self, turn: Turn, t0: float, knots: Knots, noise: np.ndarray | None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One turn from ``t0``, the chair's pose interpolated in ``knots`` (times,
        increasing, x, y, heading; held past the ends) and ``noise`` (standard normal
        draws, one a sample, or None): the published ranges (float32, inf for none),
        intensities (float32), each beam's sample time (NaN for none), and each
        sample's quarter millimetres (0 for no return)."""
        job = ScanJob(self, turn, t0, noise, knots=knots)
        job.run()
        return job.ranges, job.intensities, job.beam_time, job.q2

    @property
    def items_per_cell(self) -> float:
        """The mean number of items a cell holds (each item counted in every cell it
        touches)."""
        return len(self._items) / (self.shape[0] * self.shape[1])


def integrate_motion(start: tuple[float, float, float], t0: float, log: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """``wcdrive.plant.lidar.MotionTrack``'s knots in C (times, x, y, heading, each
    ``len(log) + 1``); None without the C helper."""
    lib = load_raycast()
    if lib is None:
        return None
    log = np.ascontiguousarray(log, dtype=float)
    if log.ndim != 2 or log.shape[1] < 4:
        raise ValueError("a motion log is n x 4 at least: time, forward, lateral, yaw rate")
    n = len(log)
    out = np.empty((4, n + 1))
    lib.rc_integrate(t0, start[0], start[1], start[2], n, _address(log) if n else None, log.shape[1],
                     *(_address(out[i]) for i in range(4)))
    return out[0], out[1], out[2], out[3]


class ScanJob:
    """One lidar turn for the C scan (``RayGrid.scan``), its inputs and outputs held
    here while C reads and writes them: the poses from ``knots`` (times, x, y,
    heading) or from ``motion``, a motion log's start pose (at ``motion_t0``, ``t0``
    if None) and rows (``MotionTrack``), whose knots the job integrates (``knots``
    once run); the noise ``noise`` (standard
    normal draws, one a sample), or drawn by the job from ``draw`` (where
    ``draws_in_c()``: ``Generator.standard_normal``'s draws, made in C when the job is
    made, the generator the job's until then; jobs on one pipe draw in the order
    submitted). ``run`` makes it now; a ``ScanPipe`` makes it on its thread."""

    def __init__(self, grid: RayGrid, turn: Turn, t0: float, noise: np.ndarray | None, *,
                 knots: Knots | None = None,
                 motion: tuple[tuple[float, float, float], np.ndarray] | None = None,
                 motion_t0: float | None = None, draw: np.random.Generator | None = None) -> None:
        if (knots is None) == (motion is None):
            raise ValueError("a scan job's poses: knots or a motion log, one of them")
        if draw is not None and noise is not None:
            raise ValueError("a scan job's noise: given, or drawn, not both")
        self._grid, self._turn = grid, turn
        s = JobStruct(grid=ctypes.addressof(grid._struct), lidar=ctypes.addressof(turn.struct), t0=t0)
        self._log: np.ndarray | None = None
        if motion is not None:
            start, log = motion
            self._log = np.ascontiguousarray(log, dtype=float)
            if self._log.ndim != 2 or self._log.shape[1] < 4:
                raise ValueError("a motion log is n x 4 at least: time, forward, lateral, yaw rate")
            rows = len(self._log)
            self._knots = np.empty((4, rows + 1))
            s.log = _address(self._log) if rows else None
            s.log_rows, s.log_stride = rows, self._log.shape[1]
            s.start_x, s.start_y, s.start_h = start
            s.log_t0 = t0 if motion_t0 is None else motion_t0
        else:
            assert knots is not None
            k = [np.ascontiguousarray(a, dtype=float) for a in knots]
            if len(k) != 4 or len(k[0]) == 0 or not all(a.shape == k[0].shape for a in k) or k[0].ndim != 1:
                raise ValueError("knots: four arrays of one length, one knot at least")
            self._knots = np.stack(k)
        s.n = n = self._knots.shape[1]
        at = _address(self._knots)              # (4, n), C-ordered: a row every 8 n bytes
        s.kt, s.kx, s.ky, s.kh = at, at + 8 * n, at + 16 * n, at + 24 * n
        self._noise = None
        if noise is not None:
            self._noise = np.ascontiguousarray(noise, dtype=float)
            if len(self._noise) < turn.samples:
                raise ValueError(f"noise: {turn.samples} draws needed, {len(self._noise)} given")
            s.noise = _address(self._noise)
        self._draw = draw
        samples, beams = turn.samples, turn.beams
        # three blocks: what a scan publishes (ranges and intensities; the beam times),
        # and the job's own (the samples' quarter millimetres and the draws)
        published = np.empty(2 * beams, dtype=np.float32)
        self.beam_time = np.empty(beams)
        own = np.empty(samples if draw is not None else 0, dtype=np.float64)
        q2 = np.empty(samples, dtype=np.int32)
        at = _address(published)
        if draw is not None:
            if not grid._lib.rc_draws():
                raise ValueError("this C scan cannot draw its noise: draw it with numpy")
            self._noise = own
            s.bitgen = draw.bit_generator.ctypes.bit_generator.value
            s.draws = _address(own)
        #: each sample's quarter millimetres (0: none)
        self.q2 = q2
        #: the published ranges (float32 m, inf for none), intensities, beam times (NaN for none)
        self.ranges = published[:beams]
        self.intensities = published[beams:]
        s.q2, s.ranges, s.intensities = _address(q2), at, at + 4 * beams
        s.beam_time = _address(self.beam_time)
        self.struct = s

    @property
    def integrated(self) -> bool:
        """Whether the job integrates a motion log into its knots."""
        return self._log is not None

    @property
    def knots(self) -> Knots:
        """The poses' knots (a motion log's once the job has run)."""
        k = self._knots
        return k[0], k[1], k[2], k[3]

    def run(self) -> None:
        """Makes the turn now, in this thread."""
        self._grid._lib.rc_run(ctypes.byref(self.struct))


class ScanPipe:
    """A C thread that makes the jobs (``ScanJob``) submitted to it, in order, while the
    caller runs on (ctypes lets go of the GIL; the thread never takes it); ``wait``
    makes what is left of the job meanwhile (so two cores make it). A job is not to be
    read or run until waited for; one not waited for is kept until ``close``, which
    finishes what is queued and stops the thread. Raises ``OSError`` without the C
    helper or a thread."""

    def __init__(self) -> None:
        self._pipe: int | None = None
        lib = load_raycast()
        if lib is None:
            raise OSError("no C ray cast: no scan thread")
        self._lib = lib
        self._pipe = lib.rc_pipe_open()
        if not self._pipe:
            raise OSError("no scan thread could be started")
        self._pending: dict[int, ScanJob] = {}

    @classmethod
    def open(cls) -> ScanPipe | None:
        """A pipe, or None where none can be had (no C helper, no thread)."""
        try:
            return cls()
        except OSError:
            return None

    def submit(self, job: ScanJob) -> None:
        """Queues ``job``; its arrays are not to be read until ``wait``."""
        if self._pipe is None:
            raise ValueError("the scan pipe is closed")
        if id(job) in self._pending:
            raise ValueError("that job is already queued")
        self._pending[id(job)] = job
        self._lib.rc_pipe_submit(self._pipe, ctypes.byref(job.struct))

    def wait(self, job: ScanJob) -> ScanJob:
        """``job`` once made (at once if it was)."""
        if self._pending.pop(id(job), None) is not None and self._pipe is not None:
            self._lib.rc_pipe_wait(self._pipe, ctypes.byref(job.struct))
        return job

    def close(self) -> None:
        """Finishes the queued jobs and stops the thread (again: nothing)."""
        if self._pipe is not None:
            self._lib.rc_pipe_close(self._pipe)
            self._pipe = None
            self._pending.clear()

    def __enter__(self) -> ScanPipe:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        self.close()
