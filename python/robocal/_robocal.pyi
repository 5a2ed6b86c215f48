"""Type stubs of robocal._robocal, the native module (python/src/lib.rs). Use the public API in
``robocal`` (robocal/__init__.py); these are its building blocks. Units: m, rad, s, kg, °C."""

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

VERSION: str
CAUSES: list[str]
"""The cause words of ``model=`` (``joint_compliance``, …), from calib's registry, in the order
diagnose tries them."""
LEARNED_KINDS: list[str]
"""The learned residual kinds, written ``learned:KIND`` in ``model=``."""

class Robot:
    """A robot: the serial chain of a URDF (built-in or a file), with its URDF text."""

    @staticmethod
    def load(robot: str = "iiwa7", base_link: str | None = None, tip_link: str | None = None) -> Robot:
        """A URDF file path or a built-in name (iiwa7, ur5, ur10, wam); the chain runs from
        ``base_link`` (default: the root link) to ``tip_link`` (default: the single leaf link).
        Raises BadInput for an unknown name, an unreadable or unusable URDF."""
    @property
    def name(self) -> str: ...
    @property
    def joint_names(self) -> list[str]:
        """Joint names, base to tip."""
    @property
    def dof(self) -> int:
        """Number of joints of the chain."""
    @property
    def base_link(self) -> str: ...
    @property
    def tip_link(self) -> str: ...
    @property
    def source(self) -> str:
        """A file path or ``built-in robot 'NAME'``."""
    @property
    def urdf(self) -> str: ...
    @property
    def limits(self) -> npt.NDArray[np.float64]:
        """dof x 2: lower and upper limit per joint (rad, or m for prismatic joints); NaN without."""
    def fk(self, q: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """``T_base_flange`` at ``q`` (rad or m): 4x4 homogeneous (m) for one configuration (dof,),
        N x 4 x 4 for N configurations (N, dof). A value beyond a joint limit gives a DataWarning."""
    def jacobian(self, q: npt.ArrayLike, frame: str = "spatial") -> npt.NDArray[np.float64]:
        """6 x dof flange Jacobian at ``q``, rows ``[ω; v]`` (angular first; rad/s and m/s per unit
        q̇). ``frame``: ``"spatial"`` (base frame, velocity of the point at the base origin),
        ``"body"`` (flange frame) or ``"local_world_aligned"`` (flange origin, base axes). Pinocchio
        orders ``[v; ω]``: its WORLD Jacobian is ``J[[3, 4, 5, 0, 1, 2]]`` of ``"spatial"``."""

class Table:
    """A measurement table held by the Rust side (``shared/spec/measurements.md``)."""

    @staticmethod
    def read(path: str, configurations: bool = False) -> Table:
        """A ``.csv`` or ``.parquet`` file, read and checked as the command line reads it."""
    @staticmethod
    def from_columns(
        columns: Sequence[tuple[str, npt.NDArray[Any] | str, int | None]],
        source: str,
        configurations: bool = False,
    ) -> Table:
        """Columns ``(name, contiguous 1-D numeric array or a type name, first null index)``; the
        errors of a file with these columns, naming ``source``, the row (from 1) and the column."""
    def columns(self) -> list[tuple[str, npt.NDArray[Any]]]:
        """The columns in file order: ``pose`` int64, ``dir*`` int8, the rest float64."""
    @property
    def source(self) -> str: ...
    @property
    def n_joints(self) -> int: ...
    @property
    def n_poses(self) -> int: ...
    def __len__(self) -> int: ...

class CalibratedModel:
    """A calibrated model, the content of the command line's MODEL.json."""

    @staticmethod
    def load(path: str) -> CalibratedModel: ...
    def save(self, path: str) -> None: ...
    def to_json(self) -> str: ...
    def predict(self, table: Table) -> list[tuple[str, npt.NDArray[Any]]]:
        """``pose, x, y, z`` (and ``qw, qx, qy, qz``): tracker frame, m."""
    def predict_file(self, data: str, out: str, chunk_rows: int) -> tuple[int, int]:
        """``robocal predict`` file to file, streamed: (rows, rows outside the support)."""
    @property
    def robot(self) -> str: ...
    @property
    def model(self) -> str: ...

def calibrate(
    robot: Robot, data: Table, test: Table | None, args: list[str]
) -> tuple[CalibratedModel | None, str, str | None]:
    """``robocal calibrate`` with value flags ``args``: (model, report JSON, failure message)."""

def calibrate_file(
    robot: Robot, path: str, args: list[str], stream: str, chunk_rows: int
) -> tuple[CalibratedModel | None, str, str | None] | None:
    """``robocal calibrate --data PATH --stream STREAM`` when that reads the file in pieces: (model,
    report JSON, failure message); None when the table is to be held in memory."""

def diagnose(robot: Robot, data: Table, args: list[str]) -> str:
    """``robocal diagnose --json`` with value flags ``args``: the JSON text."""

def register(model: CalibratedModel, data: Table, args: list[str]) -> tuple[CalibratedModel, str]:
    """``robocal register`` with value flags ``args``: (model with the campaign registered, the
    ``register --json`` document)."""

def generate(scenario: str, out: str, args: list[str]) -> str:
    """``robocal generate --scenario SCENARIO --out OUT --json`` with value flags ``args``."""

def register_file(model: CalibratedModel, path: str, args: list[str], stream: str,
                  chunk_rows: int) -> tuple[CalibratedModel, str] | None:
    """``robocal register --data PATH --stream STREAM --json`` when that streams, else None."""

def plan_poses(robot: Robot, candidates: Table | None, args: list[str]) -> tuple[str, str]:
    """``robocal plan-poses --json`` with value flags ``args``: (the pose file's CSV text, the JSON
    document)."""

def options(command: str) -> list[str]:
    """The keyword options (value flags) of ``calibrate``, ``compensate``, ``diagnose``,
    ``generate``, ``plan_poses`` or ``register``."""

def builtin_robots() -> list[str]: ...
