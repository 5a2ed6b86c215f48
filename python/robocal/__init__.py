"""robocal from Python: the same engine as the ``robocal`` command line, on numpy and pandas.

Simulate laser-tracker campaigns with known injected errors, calibrate a robot's kinematic error model
from measurements, predict, and diagnose what the model still gets wrong::

    import robocal
    robot = robocal.Robot.load("iiwa7")                 # built-in name or URDF path
    T = robot.fk([0, 0.5, 0, -1.2, 0, 0.8, 0])          # T_base_flange, 4x4 numpy (m)
    ds = robocal.generate("scenarios/iiwa7_all.toml", seed=7)
    model = robocal.calibrate(ds.measurements, robot="iiwa7", model="kinematic")
    model.report["validation"]["after"]["rms_m"]       # 5-fold cross-validated RMS error (m)
    robocal.diagnose(ds.measurements, robot="iiwa7")["findings"]

Units are SI (m, rad, s, kg, °C); positions are in the tracker frame, ``T_base_flange`` in the robot's
base frame. Measurement tables follow the contract of the command line (columns ``pose, q1..qN, x, y,
z`` and optionally ``qw..qz, t, temp, dir1..dirN, payload, sigma, campaign``). Options have the names of the
command line's flags (``test_fraction=`` for ``--test-fraction``). Errors raise :class:`BadInput`
(the command line's exit 2) or :class:`RuntimeFailure` (exit 1) with the command line's message.
Long work releases the GIL, and Ctrl-C interrupts it (``KeyboardInterrupt``). See docs/python.md.
"""

from __future__ import annotations

import io
import json
import os
import tempfile
from typing import Any

from . import _robocal
from ._data import DataLike, flags, to_frame, to_table
from ._errors import BadInput, DataWarning, Error, RuntimeFailure
from ._robocal import Robot, Table

__all__ = [
    "BadInput",
    "DataLike",
    "DataWarning",
    "Dataset",
    "Error",
    "Model",
    "Robot",
    "RuntimeFailure",
    "Table",
    "__version__",
    "calibrate",
    "diagnose",
    "generate",
    "load_model",
    "options",
    "plan_poses",
    "read_table",
    "register",
]

__version__: str = _robocal.VERSION


def _robot(robot: str | os.PathLike[str] | Robot) -> Robot:
    if isinstance(robot, Robot):
        return robot
    return Robot.load(os.fspath(robot))


def _check_options(command: str, given: dict[str, Any]) -> None:
    """A keyword that is not an option of ``command`` is a TypeError, as for any Python function."""
    known = _robocal.options(command)
    for key in given:
        if key not in known:
            raise TypeError(
                f"{command}() got an unexpected keyword argument '{key}' (options: {', '.join(known)})"
            )


def options(command: str) -> list[str]:
    """The keyword options of ``command`` (``"calibrate"``, ``"compensate"``, ``"diagnose"``,
    ``"generate"``, ``"plan_poses"``, ``"register"``): the command line's value flags, ``--test-fraction`` as ``test_fraction``."""
    return list(_robocal.options(command))


def read_table(path: str | os.PathLike[str], *, configurations: bool = False) -> "pd.DataFrame":
    """A measurement table file (``.csv`` or ``.parquet``) as a pandas DataFrame, read and checked as
    the command line reads it (``pose`` int64, ``dir*`` int8, every other column float64). With
    ``configurations``, ``x, y, z`` may be absent (joint configurations for :meth:`Model.predict`)."""
    return to_frame(_robocal.Table.read(os.fspath(path), configurations).columns())


class Dataset:
    """A generated campaign: what ``robocal generate`` writes.

    Attributes:
        measurements: the measurement table (pandas DataFrame, the contract's columns: ``pose``,
            ``q1..qN`` in rad, ``x, y, z`` in m in the tracker frame, ``t`` in s, ``temp`` in °C,
            ``dir1..dirN``, ``payload`` in kg, ``sigma`` in m, ``qw..qz`` with a 6-DoF probe).
        truth: the ground truth, the ``truth.json`` document (every injected parameter, the scenario,
            seeds, software version, tracker placement).
        summary: the ``generate --json`` summary (effect sizes, noise, outliers).
        path: the folder holding ``measurements.parquet``, ``truth.json`` and ``truth.parquet`` when
            ``generate`` was given ``out=``, else None.
    """

    def __init__(
        self,
        measurements: "pd.DataFrame",
        truth: dict[str, Any],
        summary: dict[str, Any],
        path: str | None,
    ) -> None:
        self.measurements = measurements
        self.truth = truth
        self.summary = summary
        self.path = path

    def __repr__(self) -> str:
        return (
            f"Dataset({self.summary.get('robot')!r}, {self.summary.get('poses')} poses, "
            f"{len(self.measurements)} rows, seed {self.summary.get('seed')})"
        )


def generate(
    scenario: str | os.PathLike[str],
    *,
    seed: int | None = None,
    poses: int | None = None,
    out: str | os.PathLike[str] | None = None,
    **options: Any,
) -> Dataset:
    """Simulates the campaign of a scenario file (TOML, see ``scenarios/``) as ``robocal generate``.

    Args:
        scenario: the scenario file.
        seed: replaces the scenario's seed (every random draw follows from it: same seed, same data).
        poses: replaces the scenario's number of poses.
        out: a folder to keep the three files in (created if missing; as ``generate --out``); by default
            they are written to a temporary folder and removed after reading.
        **options: further ``generate`` flags, e.g. ``noise=0`` (multiplier on the tracker noise).

    Returns:
        The :class:`Dataset`: ``measurements`` (DataFrame), ``truth`` (dict, as ``truth.json``).
    """
    options = {"seed": seed, "poses": poses, **options}
    _check_options("generate", options)
    args = flags(options)

    def run(folder: str) -> Dataset:
        summary = json.loads(_robocal.generate(os.fspath(scenario), folder, args))
        table = _robocal.Table.read(os.path.join(folder, "measurements.parquet"))
        with open(os.path.join(folder, "truth.json"), encoding="utf-8") as f:
            truth = json.load(f)
        return Dataset(to_frame(table.columns()), truth, summary, None)

    if out is not None:
        ds = run(os.fspath(out))
        ds.path = os.fspath(out)
        return ds
    with tempfile.TemporaryDirectory(prefix="robocal_") as folder:
        return run(os.path.join(folder, "dataset"))


class Model:
    """A calibrated model: what ``robocal calibrate --out MODEL.json`` writes (the robot is embedded).

    Attributes:
        report: the ``calibrate --json`` document of the calibration that made it (``out`` and
            ``urdf_out`` are None: nothing was written); None for a model read by :func:`load_model`.
    """

    def __init__(self, native: _robocal.CalibratedModel, report: dict[str, Any] | None) -> None:
        self._native = native
        self.report = report

    @property
    def robot(self) -> str:
        """The calibrated robot's name."""
        return self._native.robot

    @property
    def model(self) -> str:
        """The fitted model: ``kinematic``, ``kinematic+joint_compliance``, …"""
        return self._native.model

    def predict(self, data: DataLike) -> "pd.DataFrame":
        """Where the calibrated robot puts the target for each row of ``data``, as ``robocal
        predict``: a DataFrame ``pose, x, y, z`` (tracker frame, m) and ``qw, qx, qy, qz`` when the
        model has orientation. ``data`` needs ``pose, q1..qN`` (rad) and what the model's causes read
        (``temp`` or ``t``, ``dir1..dirN``, ``payload``); ``x, y, z`` are ignored when present. Each
        row is predicted in the tracker frame of its ``campaign`` (an id the model knows); rows
        without that column in the model's default campaign (the one :meth:`register` added last).

        Two more columns, as the command writes them: ``sigma_m``, each row's predicted standard
        deviation (m) from the parameter covariance, with a 1 mm / 1 mrad prior on what the
        calibration data did not determine (absent for a model file without a covariance); and
        ``outside_support`` (0 or 1): the row lies beyond the configurations the learned correction
        was fitted on (the correction is off there) or its ``sigma_m`` exceeds three times the
        model's held-out error."""
        return to_frame(self._native.predict(to_table(data, configurations=True)))

    def predict_file(self, data: str | os.PathLike[str], out: str | os.PathLike[str],
                     chunk_rows: int = 65_536) -> int:
        """:meth:`predict` from the file ``data`` (CSV or Parquet) to the CSV file ``out``, as
        ``robocal predict --data DATA --out OUT`` writes it (the same bytes), streamed: the file is
        read, predicted and written ``chunk_rows`` rows at a time, so memory stays bounded whatever
        its length (10⁷ rows in about 53 MB). ``out`` is written atomically. Returns the number of
        rows predicted; a bad row raises :class:`robocal.BadInput` naming its file-wide row (and
        leaves ``out`` as it was); the checks' warnings go to stderr, as the command's do."""
        rows, _outside = self._native.predict_file(os.fspath(data), os.fspath(out), int(chunk_rows))
        return rows

    def compensate(self, data: DataLike, **options: Any) -> "pd.DataFrame":
        """The joints to command so that the calibrated robot puts the target where it should be, as
        ``robocal compensate``: every part of the model inverted (geometry, each cause at the row's
        payload, temperature or time and approach direction, the learned correction).

        ``data`` needs ``pose``, ``x, y, z`` (where the target should be, m, in the tracker frame of
        the row's campaign; ``frame="base"`` for the robot's base frame), ``q1..qN`` (the nominal
        joints: the seed, and the answer is the solution nearest them), optionally ``qw..qz`` (a
        model with orientation), and the context columns the model reads (``payload``, ``temp`` or
        ``t``, ``dir1..dirN``, ``campaign``). With ``program=True`` it is a nominal joint program
        (no ``x, y, z``): the targets are where the nominal robot puts the target, registered to the
        calibrated robot.

        Returns:
            A DataFrame ``pose, q1..qN, residual_m, outside_support, converged`` and the input's
            context columns. A row not reached (out of reach, beyond the joint limits) has
            ``converged == 0`` and is named in a ``DataWarning``.
        """
        _check_options("compensate", options)
        columns, _failures = self._native.compensate(
            to_table(data, configurations=bool(options.get("program"))), flags(options)
        )
        return to_frame(columns)

    def register(self, data: DataLike, stream: str = "auto", chunk_rows: int = 65536,
                 **options: Any) -> "Model":
        """A new measurement campaign (the tracker was moved), as ``robocal register``: the
        tracker-to-base transform (and with ``target=True`` the target offset) fitted to ``data``,
        every robot parameter kept. ``campaign=ID`` refits a campaign the model knows instead.

        Given a ``.csv``/``.parquet`` path, the file is read in pieces as ``register --stream``
        reads it (``stream="auto"``: above 262,144 rows; ``"always"``; ``"never"``), in bounded
        memory, and ``report["stream"]`` says so; a DataFrame stays in memory.

        Returns:
            The model with the campaign registered (its default campaign); ``report`` is the
            ``register --json`` document (``model``, ``out``: None), with the registration residual,
            the tracker pose's σ and a warning when the robot seems to have changed.
        """
        _check_options("register", options)
        if isinstance(data, (str, os.PathLike)):
            streamed = _robocal.register_file(self._native, os.fspath(data), flags(options), stream,
                                              chunk_rows)
            if streamed is not None:
                native, report = streamed
                return Model(native, json.loads(report))
        elif stream == "always":
            raise BadInput("stream='always' reads a .csv or .parquet file in pieces, but data is not "
                           "a file path: a DataFrame is in memory already")
        elif stream not in ("auto", "never"):
            raise BadInput(f"stream='{stream}': one of 'auto', 'always' or 'never'")
        native, report = _robocal.register(self._native, to_table(data), flags(options))
        return Model(native, json.loads(report))

    def save(self, path: str | os.PathLike[str]) -> None:
        """Writes the model file: the same bytes as ``robocal calibrate --out`` for the same
        calibration (written atomically)."""
        self._native.save(os.fspath(path))

    def to_json(self) -> str:
        """The model file's text."""
        return self._native.to_json()

    def __repr__(self) -> str:
        return f"Model({self.model!r} of robot {self.robot!r})"


def load_model(path: str | os.PathLike[str]) -> Model:
    """Reads a model file written by ``robocal calibrate --out`` or :meth:`Model.save`."""
    return Model(_robocal.CalibratedModel.load(os.fspath(path)), None)


def register(model: Model, data: DataLike, **options: Any) -> Model:
    """:meth:`Model.register`: ``model`` with the campaign measured in ``data`` registered."""
    return model.register(data, **options)


def calibrate(
    data: DataLike,
    *,
    robot: str | os.PathLike[str] | Robot = "iiwa7",
    model: str = "kinematic",
    test_data: DataLike | None = None,
    stream: str = "auto",
    chunk_rows: int = 65536,
    **options: Any,
) -> Model:
    """Identifies the robot's error model from measurements, as ``robocal calibrate``.

    Args:
        data: the measurements (DataFrame, dict of arrays, ``.csv``/``.parquet`` path, Dataset).
        robot: a built-in robot name, a URDF path or a :class:`Robot` (for ``base_link``/``tip_link``).
        model: {model_words}
        test_data: held-out measurements for validation instead of cross-validation.
        **options: the other ``calibrate`` flags: ``folds=5`` (k-fold cross-validation by pose, 0 for
            none), or ``test_fraction=0.3`` (one split instead), ``regions=5`` (also hold out
            regions of the configuration space, 0 for none: ``validation.new_region``), ``seed=0``
            (of the folds or the split and the regions), ``per_campaign_target=True`` (each campaign its own target),
            ``robust="huber"|"cauchy"``; :func:`options` lists them. The model is fitted on every
            pose of ``data`` whichever validation is chosen; a ``campaign`` column gives each
            campaign its own tracker registration.
        stream: for a ``.csv``/``.parquet`` path, whether the file is read in pieces, as
            ``calibrate --stream``: ``"auto"`` (files of more than 262,144 rows when the options allow
            it: the kinematic model, no ``robust``, no ``test_fraction``, no test data; folds and
            regions validate the stream), ``"always"`` (any
            file; options that need the table in memory raise ``BadInput``) or ``"never"``. Memory
            then grows by 8 bytes a row only (10⁷ rows: about 160 MB). A DataFrame is in memory
            already: ``"always"`` with one raises ``BadInput``.
        chunk_rows: rows read at a time when streaming.

    Returns:
        The :class:`Model`, with ``report`` (dict, as ``calibrate --json``; ``validation`` holds the
        held-out RMS, mean, max and ISO 9283-style mean before and after; a streamed fit adds
        ``stream``: rows, passes, piece and sample sizes).

    Raises:
        BadInput: unusable data or options (the message names the column, row and field).
        RuntimeFailure: the calibration did not converge (``report`` attribute) or failed.
    """
    options = {"model": model, **options}
    _check_options("calibrate", options)
    rob = _robot(robot)
    if isinstance(data, (str, os.PathLike)) and test_data is None:
        streamed = _robocal.calibrate_file(rob, os.fspath(data), flags(options), stream, chunk_rows)
        if streamed is not None:
            native, report_text, failure = streamed
            report = json.loads(report_text)
            if failure is not None:
                raise RuntimeFailure(failure, report)
            return Model(native, report)
    elif stream == "always":
        what = "test_data is given" if test_data is not None else "data is not a file path"
        raise BadInput(
            f"stream='always' reads a .csv or .parquet file in pieces, but {what}: a DataFrame is in "
            "memory already, and held-out data needs the table in memory"
        )
    elif stream not in ("auto", "never"):
        raise BadInput(f"stream='{stream}': one of 'auto', 'always' or 'never'")
    table = to_table(data)
    test = None if test_data is None else to_table(test_data)
    native, report_text, failure = _robocal.calibrate(rob, table, test, flags(options))
    report = json.loads(report_text)
    if failure is not None:
        raise RuntimeFailure(failure, report)
    return Model(native, report)


def plan_poses(
    robot: str | os.PathLike[str] | Robot = "iiwa7",
    *,
    select: int,
    candidates: DataLike | None = None,
    **options: Any,
) -> "pd.DataFrame":
    """The poses (and payloads) to measure, as ``robocal plan-poses``: ``select`` of them, chosen for
    the model's parameters among drawn candidates or ``candidates`` (the robot's own reachable poses:
    a DataFrame, dict of arrays or ``.csv``/``.parquet`` path with ``pose, q1..qN``; ``x, y, z`` and
    the context columns ``payload``, ``temp``, ``t``, ``dir1..dirN`` optional).

    Args:
        robot: a built-in robot name, a URDF path or a :class:`Robot`.
        select: how many poses.
        candidates: the robot's own poses to choose from, or ``None`` for ``candidates=2000`` drawn.
        **options: the other ``plan-poses`` flags: ``model="kinematic+joint_compliance"``,
            ``criterion="d"|"a"|"e"``, ``candidates`` (a count, when drawn), ``payloads=[0, 3.5, 7]``
            (kg, one chosen per pose), ``payload_com=(0, 0, 0.08)`` (flange frame, m), ``seed``,
            ``target_offset=(x, y, z)``, ``noise`` and ``noise_per_m`` (m), ``tracker=(x, y, z)``
            (base frame, m) with ``tracker_range=(min, max)`` and ``line_of_sight`` (clearance, m),
            ``floor`` (m), ``joint_margin`` (rad); :func:`options` lists them.

    Returns:
        A DataFrame ``pose, q1..qN`` (and ``payload`` when chosen or given, and the candidates'
        context columns) to measure in that order, also a pose file for ``generate``. Its
        ``attrs["plan"]`` is the ``plan-poses --json`` document's ``plan``: the criterion against
        random subsets, the predicted held-out error (``position_sigma_m``,
        ``predicted_heldout_rms_m``), every parameter's predicted ``sigma`` beside ``random_sigma``,
        and what each constraint ``rejected``.

    Raises:
        BadInput: unusable candidates or options (the message names the flag, the column or row).
    """
    import pandas as pd

    if isinstance(candidates, int):
        raise BadInput(
            f"candidates={candidates}: give the number of drawn candidates as candidates_count=..."
        )
    count = options.pop("candidates_count", None)
    if count is not None:
        options["candidates"] = count
    options = {"select": select, **options}
    _check_options("plan_poses", options)
    rob = _robot(robot)
    table = None if candidates is None else to_table(candidates, configurations=True)
    text, document = _robocal.plan_poses(rob, table, flags(options))
    frame = pd.read_csv(io.StringIO(text))
    frame.attrs["plan"] = json.loads(document)["plan"]
    return frame


def diagnose(
    data: DataLike,
    *,
    robot: str | os.PathLike[str] | Robot = "iiwa7",
    stream: str = "auto",
    sample_rows: int = 100_000,
    chunk_rows: int = 65_536,
    **options: Any,
) -> dict[str, Any]:
    """What the kinematic model misses, its cause and the gain on held-out poses, as ``robocal
    diagnose --json`` (the diagnose contract: ``steps``, ``findings``, ``unexplained``, in m).

    Args:
        data: the measurements (DataFrame, dict of arrays, ``.csv``/``.parquet`` path, Dataset).
        robot: a built-in robot name, a URDF path or a :class:`Robot`.
        stream: for a ``.csv``/``.parquet`` path, whether the file is read in pieces, as ``diagnose
            --stream``: ``"auto"`` (files of more than 262,144 rows), ``"always"`` or ``"never"``.
            Streamed, a seeded sample of whole poses (about ``sample_rows`` rows) is diagnosed and
            every other row predicted by the kinematic and the adopted model fitted on the sample:
            the document gains ``stream`` (``rows``, ``sample_rows``, ``rest``: the held-out
            statistics of the rest of the file and the adopted model's ``gain``).
        sample_rows: rows of the sample a streamed diagnosis diagnoses.
        chunk_rows: rows read at a time when streaming.
        **options: the ``diagnose`` flags: ``test_fraction=1/3``, ``seed=0``, ``alpha=1e-3``,
            ``noise_floor=None`` (m), ``screen_poses=3000`` (above it the candidates are tried on a
            subsample and the adopted models refitted on every pose); :func:`options` lists them.
    """
    _check_options("diagnose", options)
    rob = _robot(robot)
    if isinstance(data, (str, os.PathLike)):
        streamed = _robocal.diagnose_file(
            rob, os.fspath(data), flags(options), stream, sample_rows, chunk_rows
        )
        if streamed is not None:
            return json.loads(streamed)
    elif stream == "always":
        raise BadInput(
            "stream='always' reads a .csv or .parquet file in pieces, but data is not a file path: a "
            "DataFrame is in memory already"
        )
    elif stream not in ("auto", "never"):
        raise BadInput(f"stream='{stream}': one of 'auto', 'always' or 'never'")
    return json.loads(_robocal.diagnose(rob, to_table(data), flags(options)))


try:  # for the type annotations only
    import pandas as pd  # noqa: F401
except ImportError:  # pragma: no cover
    pass


def _model_words() -> str:
    """The ``model:`` entry of :func:`calibrate`'s docstring, from the native module's lists (calib's
    cause and learned-kind registries), so that a cause added there is named here."""
    causes = list(_robocal.CAUSES)
    example = "+".join(["kinematic", *causes[:2]])
    return (
        f"``kinematic`` (default), a ``+``-joined extension such as ``{example}`` with any of the\n"
        f"            causes {', '.join(f'``{c}``' for c in causes)} (each at only some of its\n"
        f"            joints with ``@``, 1-based: ``{causes[0]}@2,4``), a learned residual\n"
        f"            ``learned:{'|'.join(_robocal.LEARNED_KINDS)}``, or ``auto`` (what diagnose chooses,\n"
        "            then the learned residual when it pays)."
    )


if calibrate.__doc__:  # None under python -OO
    calibrate.__doc__ = calibrate.__doc__.replace("{model_words}", _model_words())
