"""The Grasp record shared by the whole project, and the DexGraspBench per-grasp layout.

A grasp is what a controller executes: the wrist pose and the finger joint values of three
configurations, pregrasp -> grasp -> squeeze (BODex's rule: squeeze = 2 x grasp - pregrasp with
the grasp's wrist). Poses are position xyz plus quaternion wxyz in the world (or object) frame;
joint values follow the hand's grasp joint order (`hand.joint_names`).

Records save and load as JSON or NPZ without pickle, so files are safe to share.
"""

from __future__ import annotations

import io
import json
import os
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from models.errors import GraspError

PHASES: tuple[str, ...] = ("pregrasp", "grasp", "squeeze")
ROOT_SIZE = 7  # xyz + quaternion wxyz, DexGraspBench's root layout


def _numbers(value: Any, name: str) -> np.ndarray:
    """`value` as a float array; GraspError for text, booleans, complex or ragged input."""
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError) as err:
        raise GraspError(f"{name}: not a rectangular array of numbers ({err})") from None
    if raw.dtype.kind not in "iuf":
        kinds = {"b": "booleans", "c": "complex numbers", "U": "text", "S": "bytes"}
        raise GraspError(
            f"{name}: expected numbers, got {kinds.get(raw.dtype.kind, f'dtype {raw.dtype}')}"
        )
    return raw.astype(np.float64)


def _vector(value: Any, name: str, size: int | None = None) -> np.ndarray:
    """A finite float vector of the given size, or a GraspError that names the field."""
    arr = _numbers(value, name)
    if arr.ndim != 1:
        raise GraspError(f"{name}: expected a 1-D vector, got shape {arr.shape}")
    if size is not None and arr.shape[0] != size:
        raise GraspError(f"{name}: expected {size} values, got {arr.shape[0]}")
    if not np.all(np.isfinite(arr)):
        raise GraspError(f"{name}: contains NaN or infinite values: {arr.tolist()}")
    return arr.copy()


def _quaternion(value: Any, name: str) -> np.ndarray:
    quat = _vector(value, name, 4)
    norm = float(np.linalg.norm(quat))
    if norm < 1e-8:
        raise GraspError(f"{name}: zero quaternion (expected w, x, y, z with unit norm)")
    return quat / norm


@dataclass
class Grasp:
    """One grasp: wrist pose and joint values of the pregrasp, grasp and squeeze.

    `pregrasp_wrist_*` and `squeeze_wrist_*` default to the grasp's wrist (BODex keeps the same
    wrist for the squeeze; its pregrasp usually differs). `joint_names`, when given, records the
    joint order so that a record can be checked against a hand and exported to other layouts.
    """

    hand: str
    wrist_pos: np.ndarray
    wrist_quat: np.ndarray
    grasp: np.ndarray
    pregrasp: np.ndarray
    squeeze: np.ndarray
    pregrasp_wrist_pos: np.ndarray | None = None
    pregrasp_wrist_quat: np.ndarray | None = None
    squeeze_wrist_pos: np.ndarray | None = None
    squeeze_wrist_quat: np.ndarray | None = None
    joint_names: tuple[str, ...] | None = None
    anchors: np.ndarray | None = None
    instruction: str | None = None
    metrics: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.hand, str) or not self.hand:
            raise GraspError(f"hand: expected a non-empty hand name, got {self.hand!r}")
        self.wrist_pos = _vector(self.wrist_pos, "wrist_pos", 3)
        self.wrist_quat = _quaternion(self.wrist_quat, "wrist_quat")
        self.grasp = _vector(self.grasp, "grasp joints")
        dof = self.grasp.shape[0]
        if dof == 0:
            raise GraspError("grasp joints: empty joint vector")
        self.pregrasp = _vector(self.pregrasp, "pregrasp joints")
        self.squeeze = _vector(self.squeeze, "squeeze joints")
        for phase in ("pregrasp", "squeeze"):
            n = getattr(self, phase).shape[0]
            if n != dof:
                raise GraspError(f"{phase} joints: {n} values but the grasp has {dof}")
        for phase in ("pregrasp", "squeeze"):
            pos_name, quat_name = f"{phase}_wrist_pos", f"{phase}_wrist_quat"
            pos, quat = getattr(self, pos_name), getattr(self, quat_name)
            if pos is not None:
                setattr(self, pos_name, _vector(pos, pos_name, 3))
            if quat is not None:
                setattr(self, quat_name, _quaternion(quat, quat_name))
        if self.joint_names is not None:
            if isinstance(self.joint_names, str) or not isinstance(
                self.joint_names, Sequence | np.ndarray
            ):
                raise GraspError(
                    f"joint_names: expected a list of joint names, got {self.joint_names!r}"
                )
            if not all(isinstance(n, str | np.str_) for n in self.joint_names):
                raise GraspError("joint_names: every joint name must be a string")
            self.joint_names = tuple(str(n) for n in self.joint_names)
            if len(self.joint_names) != dof:
                raise GraspError(
                    f"joint_names: {len(self.joint_names)} names for {dof} joint values"
                )
        if self.anchors is not None:
            anchors = _numbers(self.anchors, "anchors")
            if anchors.ndim != 2 or anchors.shape[1] != 3:
                raise GraspError(f"anchors: expected shape (K, 3), got {anchors.shape}")
            if not np.all(np.isfinite(anchors)):
                raise GraspError("anchors: contains NaN or infinite values")
            self.anchors = anchors.copy()
        if self.instruction is not None and not isinstance(self.instruction, str):
            raise GraspError(f"instruction: expected a string, got {type(self.instruction)}")
        if not isinstance(self.metrics, Mapping):
            raise GraspError(f"metrics: expected a dict, got {type(self.metrics).__name__}")
        self.metrics = dict(self.metrics)

    # ------------------------------------------------------------------ access
    @property
    def dof(self) -> int:
        return int(self.grasp.shape[0])

    def joints(self, phase: str) -> np.ndarray:
        """Joint values of `phase` (one of PHASES)."""
        if phase not in PHASES:
            raise GraspError(f"unknown phase {phase!r}; expected one of {PHASES}")
        return getattr(self, phase)

    def wrist_pose(self, phase: str = "grasp") -> np.ndarray:
        """The 7-vector xyz + wxyz of the wrist in `phase` (the grasp's wrist if not set)."""
        if phase not in PHASES:
            raise GraspError(f"unknown phase {phase!r}; expected one of {PHASES}")
        pos = self.wrist_pos if phase == "grasp" else getattr(self, f"{phase}_wrist_pos")
        quat = self.wrist_quat if phase == "grasp" else getattr(self, f"{phase}_wrist_quat")
        pos = self.wrist_pos if pos is None else pos
        quat = self.wrist_quat if quat is None else quat
        return np.concatenate([pos, quat])

    def check_hand(self, joint_names: Sequence[str], hand: str | None = None) -> None:
        """Raise GraspError unless the record fits a hand with these grasp joints."""
        if len(joint_names) != self.dof:
            raise GraspError(
                f"grasp has {self.dof} joint values but hand {hand or self.hand!r} has "
                f"{len(joint_names)} joints ({', '.join(joint_names)})"
            )
        if self.joint_names is not None and tuple(joint_names) != self.joint_names:
            raise GraspError(
                f"grasp joint order {self.joint_names} differs from the hand's {tuple(joint_names)}"
            )

    @classmethod
    def with_bodex_squeeze(
        cls,
        hand: str,
        wrist_pos: Any,
        wrist_quat: Any,
        grasp: Any,
        pregrasp: Any,
        **kwargs: Any,
    ) -> Grasp:
        """A grasp whose squeeze follows BODex's rule: 2 x grasp - pregrasp, same wrist."""
        g = np.asarray(grasp, dtype=np.float64)
        p = np.asarray(pregrasp, dtype=np.float64)
        if g.shape != p.shape:
            raise GraspError(f"pregrasp shape {p.shape} differs from grasp shape {g.shape}")
        return cls(hand, wrist_pos, wrist_quat, g, p, 2.0 * g - p, **kwargs)

    def moved(self, offset: Any) -> Grasp:
        """The same grasp with every wrist pose translated by `offset` (world frame)."""
        off = _vector(offset, "offset", 3)
        d = self.to_dict()
        for key in ("wrist_pos", "pregrasp_wrist_pos", "squeeze_wrist_pos"):
            if d[key] is not None:
                d[key] = (np.asarray(d[key]) + off).tolist()
        return Grasp.from_dict(d)

    # ------------------------------------------------------------------ serialization
    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-compatible dict (lists, strings, numbers, None)."""

        def lst(a: np.ndarray | None) -> list | None:
            return None if a is None else np.asarray(a).tolist()

        return {
            "hand": self.hand,
            "wrist_pos": lst(self.wrist_pos),
            "wrist_quat": lst(self.wrist_quat),
            "pregrasp": lst(self.pregrasp),
            "grasp": lst(self.grasp),
            "squeeze": lst(self.squeeze),
            "pregrasp_wrist_pos": lst(self.pregrasp_wrist_pos),
            "pregrasp_wrist_quat": lst(self.pregrasp_wrist_quat),
            "squeeze_wrist_pos": lst(self.squeeze_wrist_pos),
            "squeeze_wrist_quat": lst(self.squeeze_wrist_quat),
            "joint_names": None if self.joint_names is None else list(self.joint_names),
            "anchors": lst(self.anchors),
            "instruction": self.instruction,
            "metrics": dict(self.metrics),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Grasp:
        if not isinstance(data, Mapping):
            raise GraspError(f"a grasp record must be a dict, got {type(data).__name__}")
        known = set(cls.__dataclass_fields__)
        unknown = set(data) - known
        if unknown:
            raise GraspError(f"unknown grasp fields {sorted(unknown)}; known: {sorted(known)}")
        missing = {"hand", "wrist_pos", "wrist_quat", "grasp", "pregrasp", "squeeze"} - set(data)
        if missing:
            raise GraspError(f"grasp record lacks required fields {sorted(missing)}")
        return cls(**dict(data))

    def to_json(self) -> str:
        return json.dumps(_jsonable(self.to_dict(), "metrics"), indent=1)

    @classmethod
    def from_json(cls, text: str) -> Grasp:
        if not isinstance(text, str):
            raise GraspError(f"a JSON grasp record is text, got {type(text).__name__}")
        try:
            data = json.loads(text)
        except json.JSONDecodeError as err:
            raise GraspError(f"not a JSON grasp record: {err}") from None
        if not isinstance(data, dict):
            raise GraspError("a JSON grasp record must be an object")
        return cls.from_dict(data)

    def to_arrays(self) -> dict[str, np.ndarray]:
        """NPZ-ready arrays: numbers as float arrays, text (and metrics) as unicode scalars."""
        out: dict[str, np.ndarray] = {}
        for key, value in self.to_dict().items():
            if value is None:
                continue
            if key in ("hand", "instruction"):
                out[key] = np.array(value)
            elif key == "metrics":
                out[key] = np.array(json.dumps(_jsonable(value, "metrics")))
            elif key == "joint_names":
                out[key] = np.array(value, dtype=str)
            else:
                out[key] = np.asarray(value, dtype=np.float64)
        return out

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray]) -> Grasp:
        data: dict[str, Any] = {}
        for key in arrays:
            value = np.asarray(arrays[key])
            if key in ("hand", "instruction", "metrics"):
                if value.ndim != 0 or value.dtype.kind != "U":
                    raise GraspError(
                        f"{key}: expected a text scalar, got {value.dtype} {value.shape}"
                    )
                value = str(value)
            if key == "metrics":
                try:
                    data[key] = json.loads(value)
                except ValueError as err:
                    raise GraspError(f"metrics: not JSON ({err})") from None
            elif key == "joint_names":
                if value.ndim != 1 or value.dtype.kind != "U":
                    raise GraspError(f"joint_names: expected a list of names, got {value.dtype}")
                data[key] = tuple(str(v) for v in value)
            else:
                data[key] = value
        return cls.from_dict(data)

    def save(self, path: str | Path) -> Path:
        """Write as .json or .npz (chosen by the suffix), creating missing folders; through a
        temporary file, so a failed write leaves no half-written record."""
        from models.paths import output_file

        path = output_file(path, (".json", ".npz"), "grasp file", GraspError)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp{path.suffix}")
        try:
            if path.suffix.lower() == ".json":
                tmp.write_text(self.to_json())
            else:
                with open(tmp, "wb") as f:
                    np.savez(f, **self.to_arrays())
            os.replace(tmp, path)
        except OSError as err:
            tmp.unlink(missing_ok=True)
            raise GraspError(f"could not write the grasp file {path}: {err}") from None
        return path

    @classmethod
    def load(cls, path: str | Path) -> Grasp:
        from models.paths import input_file

        path = input_file(path, "grasp file", GraspError)
        suffix = path.suffix.lower()
        if suffix not in (".json", ".npz"):
            raise GraspError(f"{path}: grasp files must end in .json or .npz")
        try:
            raw = path.read_bytes()
        except OSError as err:
            raise GraspError(f"{path}: cannot read the grasp file ({err.strerror})") from None
        if not raw:
            raise GraspError(f"{path} is empty (0 bytes); was it written completely?")
        if suffix == ".json":
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError:
                raise GraspError(f"{path} is not UTF-8 text; a .json grasp file is JSON") from None
            try:
                return cls.from_json(text)
            except GraspError as err:
                raise GraspError(f"{path}: {err}") from None
        try:
            with np.load(io.BytesIO(raw), allow_pickle=False) as npz:
                arrays = {k: npz[k] for k in npz.files}
        except (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile) as err:
            raise GraspError(
                f"{path}: unreadable grasp NPZ ({type(err).__name__}: {err}); is the file "
                "complete? Write it again with Grasp.save or drograsp plan --out"
            ) from None
        try:
            return cls.from_arrays(arrays)
        except GraspError as err:
            raise GraspError(f"{path}: {err}") from None


def _jsonable(value: Any, where: str) -> Any:
    """Plain JSON data: numpy arrays and scalars become lists and numbers; anything else that
    JSON cannot hold is a GraspError naming where it is."""
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v, f"{where}[{k!r}]") for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v, where) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist(), where)
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return float(value)
    if value is None or isinstance(value, str | bool | int | float):
        return value
    raise GraspError(
        f"{where}: a {type(value).__name__} cannot be saved; keep metrics to JSON data"
    )


# ---------------------------------------------------------------------- DexGraspBench layout
def _xml_index(
    joint_names: Sequence[str], xml_joint_names: Sequence[str], joint_map: Mapping[str, str] | None
) -> list[int]:
    """For each grasp joint, its index in the XML's joint order."""
    joint_map = dict(joint_map or {})
    unknown = set(joint_map) - set(joint_names)
    if unknown:
        raise GraspError(f"joint map names joints the hand lacks: {sorted(unknown)}")
    index = {name: i for i, name in enumerate(xml_joint_names)}
    out = []
    for name in joint_names:
        xml_name = joint_map.get(name, name)
        if xml_name not in index:
            raise GraspError(
                f"joint {name!r} maps to {xml_name!r}, which is not in the XML's joints "
                f"{list(xml_joint_names)}; pass a joint map"
            )
        out.append(index[xml_name])
    if len(set(out)) != len(out):
        raise GraspError("joint map sends two grasp joints to the same XML joint")
    return out


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions wxyz."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ]
    )


def _quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v rotated by the unit quaternion q (wxyz)."""
    w, u = q[0], q[1:]
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def root_offset_pose(root_offset: Any) -> np.ndarray:
    """`root_offset` (a 4x4 rigid transform, or xyz + quaternion wxyz) as a 7-vector with a
    unit quaternion; GraspError unless it is a finite rigid transform."""
    try:
        arr = np.asarray(root_offset, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise GraspError(f"root_offset: not numeric ({err})") from None
    if arr.shape == (4, 4):
        if not np.all(np.isfinite(arr)):
            raise GraspError("root_offset: contains NaN or infinite values")
        rot = arr[:3, :3]
        if (
            not np.allclose(rot.T @ rot, np.eye(3), atol=1e-6)
            or np.linalg.det(rot) < 0
            or not np.allclose(arr[3], [0.0, 0.0, 0.0, 1.0])
        ):
            raise GraspError("root_offset: the 4x4 matrix is not a rigid transform")
        from scipy.spatial.transform import Rotation

        quat = Rotation.from_matrix(rot).as_quat(scalar_first=True)
        return np.concatenate([arr[:3, 3], quat])
    if arr.shape == (ROOT_SIZE,):
        return np.concatenate(
            [_vector(arr[:3], "root_offset xyz", 3), _quaternion(arr[3:], "root_offset quaternion")]
        )
    raise GraspError(
        f"root_offset: expected a 4x4 transform or 7 values (xyz + wxyz), got shape {arr.shape}"
    )


def _compose(pose: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Pose (7) followed by offset (7): the offset's frame in the world, given `pose`'s.

    The product quaternion is left unnormalized (Grasp normalizes), so an identity offset
    returns `pose` bit for bit.
    """
    rot = pose[3:] / np.linalg.norm(pose[3:])
    pos = pose[:3] + _quat_rotate(rot, offset[:3])
    return np.concatenate([pos, _quat_mul(pose[3:], offset[3:])])


def _inverse(pose: np.ndarray) -> np.ndarray:
    conj = pose[3:] * np.array([1.0, -1.0, -1.0, -1.0])
    return np.concatenate([-_quat_rotate(conj, pose[:3]), conj])


def from_dexgraspbench(
    pregrasp_qpos: Any,
    grasp_qpos: Any,
    squeeze_qpos: Any,
    *,
    root_offset: Any,
    hand: str,
    joint_names: Sequence[str],
    xml_joint_names: Sequence[str],
    joint_map: Mapping[str, str] | None = None,
    **kwargs: Any,
) -> Grasp:
    """A Grasp from DexGraspBench's per-grasp rows (7 root values, then the XML's joints).

    The rows' root is the hand file's root frame; `root_offset` is that frame in the hand's
    root link frame (4x4 or xyz + wxyz; `models.hands.mjcf_frame.mjcf_root_offset` computes
    it from the files), so the Grasp's wrist poses are those of the root link. Pass the
    identity (`np.eye(4)`) to keep the rows' root as the wrist, e.g. for a grasp that will be
    simulated with the hand file itself. `joint_map` maps grasp joint names to XML joint
    names where they differ.
    """
    back = _inverse(root_offset_pose(root_offset))
    idx = _xml_index(joint_names, xml_joint_names, joint_map)
    rows = {}
    for phase, row in zip(PHASES, (pregrasp_qpos, grasp_qpos, squeeze_qpos), strict=True):
        rows[phase] = _vector(row, f"{phase}_qpos", ROOT_SIZE + len(xml_joint_names))
    wrist = {}
    for phase in PHASES:
        root = rows[phase][:ROOT_SIZE]
        if np.linalg.norm(root[3:]) < 1e-8:
            raise GraspError(f"{phase}_qpos: zero root quaternion (expected w, x, y, z)")
        wrist[phase] = _compose(root, back)
    return Grasp(
        hand=hand,
        wrist_pos=wrist["grasp"][:3],
        wrist_quat=wrist["grasp"][3:],
        grasp=rows["grasp"][ROOT_SIZE:][idx],
        pregrasp=rows["pregrasp"][ROOT_SIZE:][idx],
        squeeze=rows["squeeze"][ROOT_SIZE:][idx],
        pregrasp_wrist_pos=wrist["pregrasp"][:3],
        pregrasp_wrist_quat=wrist["pregrasp"][3:],
        squeeze_wrist_pos=wrist["squeeze"][:3],
        squeeze_wrist_quat=wrist["squeeze"][3:],
        joint_names=tuple(joint_names),
        **kwargs,
    )


def to_dexgraspbench(
    grasp: Grasp,
    *,
    root_offset: Any,
    xml_joint_names: Sequence[str],
    joint_names: Sequence[str] | None = None,
    joint_map: Mapping[str, str] | None = None,
    fill: float = 0.0,
) -> dict[str, np.ndarray]:
    """DexGraspBench rows {pregrasp,grasp,squeeze}_qpos for `grasp`; unmapped XML joints = fill.

    Each row's root is the hand file's root frame in the world: the grasp's wrist pose (of the
    hand's root link) composed with `root_offset`, the file's root frame in the root link frame
    (4x4 or xyz + wxyz; see `from_dexgraspbench`).
    """
    offset = root_offset_pose(root_offset)
    names = tuple(joint_names or grasp.joint_names or ())
    if not names:
        raise GraspError("to_dexgraspbench needs the grasp's joint names")
    grasp.check_hand(names)
    idx = _xml_index(names, xml_joint_names, joint_map)
    out = {}
    for phase in PHASES:
        row = np.full(ROOT_SIZE + len(xml_joint_names), fill, dtype=np.float64)
        row[:ROOT_SIZE] = _compose(grasp.wrist_pose(phase), offset)
        row[ROOT_SIZE:][idx] = grasp.joints(phase)
        out[f"{phase}_qpos"] = row
    return out
