"""SKAB (Skoltech Anomaly Benchmark): its files, its protocol, its leaderboard.

Protocol (../shared/data/skab/PROVENANCE.md, as the public leaderboard
applies it): per experiment file the first 400 rows are the training part, the
rest the test part. A detector is fitted on the training part of that file
only (labels are never an input) and then predicts 0/1 for each test row,
causally. Scores: :func:`binary_scores` (F1, FAR, MAR over all test rows of
all files pooled) and the NAB score of the predicted change points (the rows
where the 0/1 prediction switches) with a 60 s window to the right of each
true change point of the test part (:mod:`phfdi.benchmarks.scoring`).

Files: every ``*.csv`` under the data directory that has ``anomaly`` and
``changepoint`` columns is scored; a file without them (``anomaly-free.csv``)
is not part of the score (the leaderboard's 34 files exclude it) but can be
run for its false-alarm rate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Sequence

import numpy as np

from phfdi.records import read_record
from phfdi_base.errors import UserError
from wavelet_fdi.learned_detector import LearnedSettings, fit_reference, learn, run_record
from wavelet_fdi.peers import Peer, calibrate_peers, multichannel_states

from .scoring import BinaryScores, NabResult, binary_scores, match_changepoints, nab_scores, switches

TRAIN_ROWS = 400
WINDOW_S = 60.0
SENSOR_COLUMNS = ("Accelerometer1RMS", "Accelerometer2RMS", "Current", "Pressure", "Temperature", "Thermocouple",
                  "Voltage", "Volume Flow RateRMS")
LABEL_COLUMNS = ("anomaly", "changepoint")

#: the published leaderboard on the whole benchmark (34 files), as PROVENANCE.md copies it:
#: F1, FAR %, MAR %, NAB standard, NAB low FP, NAB low FN
LEADERBOARD: dict[str, tuple[float, float, float, float, float, float]] = {
    "Conv-AE": (0.78, 13.55, 28.02, 23.61, 21.54, 27.55),
    "MSET": (0.78, 39.73, 14.13, 13.84, 10.22, 17.37),
    "T-squared+Q (PCA)": (0.76, 26.62, 24.92, 25.35, 14.51, 31.33),
    "LSTM-AE": (0.74, 29.96, 25.92, 23.51, 20.11, 25.91),
    "T-squared": (0.66, 19.21, 42.6, 19.54, 10.2, 24.31),
    "MSCRED": (0.36, 49.94, 69.88, 32.42, 16.53, 40.28),
    "Isolation forest": (0.29, 2.56, 82.89, 26.16, 19.5, 30.82),
    "Null detector": (0.0, 0.0, 100.0, 0.0, 0.0, 0.0),
}


@dataclass
class SkabFile:
    """One experiment: sensor matrix (rows x 8), time stamps (s since the epoch) and, if present, labels."""

    path: Path
    group: str
    name: str
    datetime: list[str]
    time_s: np.ndarray
    values: np.ndarray
    columns: tuple[str, ...]
    anomaly: np.ndarray | None = None
    changepoint: np.ndarray | None = None

    @property
    def key(self) -> str:
        return f"{self.group}/{self.name}"

    @property
    def labelled(self) -> bool:
        return self.anomaly is not None

    def split(self, train_rows: int = TRAIN_ROWS) -> tuple[np.ndarray, np.ndarray]:
        return self.values[:train_rows], self.values[train_rows:]


def read_skab_csv(path: str | Path) -> SkabFile:
    """Read one SKAB file (``;``-separated, header row, ``datetime`` first) with the project's one reader
    (:func:`phfdi.records.read_record`); the benchmark is stricter than the reader's policy: a cell that is not a
    number, or a label other than 0 and 1, is refused (a UserError naming line and column), not marked missing."""
    p = Path(path)
    rec = read_record(p, required=SENSOR_COLUMNS)
    if rec.wall_clock is None:
        raise UserError(f"{p}: the time column must hold date-time stamps (datetime: YYYY-MM-DD hh:mm:ss)")
    present = [c for c in LABEL_COLUMNS if c in rec.signals]
    if len(present) == 1:
        raise UserError(f"{p}: has only one of the label columns {', '.join(LABEL_COLUMNS)}")
    names = [*SENSOR_COLUMNS, *present]
    table = np.column_stack([rec.signals[c] for c in names])
    holes = np.isnan(table)
    if holes.any():
        row, col = np.argwhere(holes)[0]
        raise UserError(f"{p}: line {rec.lines[row]}, column {rec.columns[names[col]]!r}: not a number")
    for c in present:
        if not np.isin(rec.signals[c], (0.0, 1.0)).all():
            raise UserError(f"{p}: column {c!r} must hold only 0 and 1")
    epoch_s = rec.wall_clock.timestamp() + rec.time_s
    stamps = [str(s).replace("T", " ") for s in np.round(epoch_s).astype("int64").astype("datetime64[s]")]
    return SkabFile(p, p.parent.name, p.stem, stamps, epoch_s, table[:, :len(SENSOR_COLUMNS)], SENSOR_COLUMNS,
                    rec.signals["anomaly"].astype(np.int8) if present else None,
                    rec.signals["changepoint"].astype(np.int8) if present else None)


def _natural(p: Path) -> tuple:
    return (p.parent.name, int(p.stem) if p.stem.isdigit() else math.inf, p.stem)


def find_files(data_dir: str | Path) -> list[Path]:
    d = Path(data_dir)
    if not d.is_dir():
        raise UserError(f"{d}: not a directory")
    files = sorted(d.rglob("*.csv"), key=_natural)
    if not files:
        raise UserError(f"{d}: no .csv files found")
    return files


#: a detector under the protocol: (training rows, test rows, test times in s) -> 0/1 per test row
Detector = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


@dataclass
class FileResult:
    file: SkabFile
    prediction: np.ndarray  # 0/1 per test row

    def labels(self) -> np.ndarray:
        return self.file.anomaly[TRAIN_ROWS:]

    def true_changepoints(self) -> np.ndarray:
        return self.file.changepoint[TRAIN_ROWS:]


@dataclass
class BenchmarkResult:
    name: str
    binary: BinaryScores
    nab: NabResult
    files: list[FileResult] = field(default_factory=list)

    def row(self) -> dict:
        return {"algorithm": self.name, "f1": self.binary.f1, "far_pct": self.binary.far_pct,
                "mar_pct": self.binary.mar_pct, **{f"nab_{k}": v for k, v in self.nab.scores.items()},
                "missed_cp": self.nab.missed, "false_positives": self.nab.false_positives,
                "windows": self.nab.windows}


def run_detector(detector: Detector, files: Iterable[SkabFile]) -> list[FileResult]:
    """Fit on each file's first 400 rows and predict its test rows (labels are not passed)."""
    out = []
    for f in files:
        if len(f.values) <= TRAIN_ROWS:
            raise UserError(f"{f.path}: {len(f.values)} rows; the protocol needs more than {TRAIN_ROWS}")
        train, test = f.split()
        pred = np.asarray(detector(train, test, f.time_s[TRAIN_ROWS:]))
        if pred.shape != (len(test),) or not np.isin(pred, (0, 1)).all():
            raise ValueError(f"{f.key}: the detector must return 0/1 per test row, got shape {pred.shape}")
        out.append(FileResult(f, pred.astype(np.int8)))
    return out


def score(name: str, results: Sequence[FileResult], width_s: float = WINDOW_S) -> BenchmarkResult:
    """F1/FAR/MAR and NAB over the labelled files of ``results``."""
    scored = [r for r in results if r.file.labelled]
    binary = binary_scores([r.labels() for r in scored], [r.prediction for r in scored])
    matched = [match_changepoints(r.file.time_s[TRAIN_ROWS:], r.true_changepoints(), switches(r.prediction), width_s)
               for r in scored]
    return BenchmarkResult(name, binary, nab_scores(matched), list(results))


def write_predictions(results: Sequence[FileResult], out_dir: str | Path) -> list[Path]:
    """OUT/predictions/<group>/<n>.csv: ``datetime;anomaly;changepoint`` for the test rows."""
    written = []
    for r in results:
        p = Path(out_dir) / "predictions" / r.file.group / f"{r.file.name}.csv"
        p.parent.mkdir(parents=True, exist_ok=True)
        cp = switches(r.prediction)
        stamps = r.file.datetime[TRAIN_ROWS:]
        lines = ["datetime;anomaly;changepoint"] + [f"{s};{int(a)};{int(c)}" for s, a, c in
                                                     zip(stamps, r.prediction, cp)]
        p.write_text("\n".join(lines) + "\n", encoding="utf-8")
        written.append(p)
    return written


# ---- label-free baselines ---------------------------------------------------------------
def null_detector(train: np.ndarray, test: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """Never alarms."""
    return np.zeros(len(test), dtype=np.int8)


def always_detector(train: np.ndarray, test: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """Alarms on every test row."""
    return np.ones(len(test), dtype=np.int8)


def random_toggler(p_flip: float, seed: int = 0) -> Detector:
    """Flips its 0/1 output with probability p_flip at each row (ignores the data; one generator per run)."""
    rng = np.random.default_rng(seed)

    def detect(train: np.ndarray, test: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        flips = rng.random(len(test)) < p_flip
        return (np.cumsum(flips) % 2).astype(np.int8)

    return detect


def hotelling_t2(quantile: float = 0.99) -> Detector:
    """Hotelling's T^2 of each test row against the training rows' mean and covariance; threshold: the
    training rows' empirical quantile (the leaderboard's 'T-squared' in its simplest form)."""

    def detect(train: np.ndarray, test: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        mu = train.mean(axis=0)
        cov = np.cov(train, rowvar=False) + 1e-9 * np.eye(train.shape[1])
        inv = np.linalg.pinv(cov)

        def t2(x: np.ndarray) -> np.ndarray:
            d = x - mu
            return np.einsum("ij,jk,ik->i", d, inv, d)

        return (t2(test) > np.quantile(t2(train), quantile)).astype(np.int8)

    return detect


# ---- our detector ---------------------------------------------------------------------
def learned_detector(settings=None) -> Detector:
    """The learned reference + multichannel wavelet-CUSUM detector (wavelet_fdi.learned_detector):
    fitted on the training rows, then run over the whole file in time order (training rows first,
    so the filters and the observer are warm), one chunk per row block; the test rows' states are
    the prediction."""

    s = settings or LearnedSettings()

    def detect(train: np.ndarray, test: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        model = learn(train, SENSOR_COLUMNS, s)
        x = np.vstack((train, test))
        t = np.arange(len(x)) * s.sample_time_s
        _, states, _ = run_record(model, t, x)
        return states[len(train):]

    return detect


# ---- the peers on the same residuals ------------------------------------------------------
#: false-alarm target of a peer over all channels together (samples at 1 Hz: about 2.8 h)
PEER_ARL0_SAMPLES = 1e4
#: calibration windows of the training rows' residuals (window maxima, exponential tail fit)
PEER_WINDOW = 50


def peer_detector(name: str, settings=None, arl0_samples: float = PEER_ARL0_SAMPLES,
                  window: int = PEER_WINDOW) -> Detector:
    """A peer change detector (wavelet_fdi.peers: CUSUM, FOCuS, Page-Hinkley, ADWIN) on the SAME residuals
    our detector sees: the learned ARX reference (same settings) fitted on the training rows, its one-step
    residuals in healthy sigmas, one copy of the peer per channel. Its threshold (ADWIN: delta) is calibrated
    on the training rows' residuals only, pooled over the channels, for a false-alarm target of
    ``arl0_samples`` for the union of the channels (each channel m * arl0), by the project's procedure
    (wavelet_fdi.peers.calibrate_peers). An alarm holds the state for ``block_samples`` rows (our clear rule)."""

    s = settings or LearnedSettings()

    def detect(train: np.ndarray, test: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        ref = fit_reference(train, SENSOR_COLUMNS, s)
        u = ref.residuals(None, np.vstack((train, test)))
        m = u.shape[1]
        healthy = [u[ref.lags:len(train), c] for c in range(m)]
        k = 0.5  # design shift: 1 healthy sigma, as in the pH-plant comparison
        cal = _calibrate_peer(name, healthy, m * arl0_samples, k, window)
        states = multichannel_states(Peer(name, cal, k), u, s.block_samples)
        return states[len(train):]

    return detect


def _calibrate_peer(name: str, streams: list[np.ndarray], arl0: float, k: float, window: int) -> float:
    return float(calibrate_peers(streams, arl0, k, window, names=(name,))[name]["threshold"])
