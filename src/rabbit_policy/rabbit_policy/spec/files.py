"""The files a controller spec names, each checked by its SHA-256 before it is used: the gait
library (its gait files and calibration) and the network's weights, a weights-only NumPy
``.npz`` (read with ``allow_pickle=False``: arrays only, no code, no torch). Not safetensors:
rosdep has no key for it, and every package.xml dependency must be one a ROS user's rosdep
can install (tests/test_manifests.py)."""

from __future__ import annotations

import hashlib
from importlib.resources import files
from pathlib import Path

import numpy as np

from rabbit_policy.runtime.gait_library import CALIBRATION_FILE, packaged_gait_dir
from rabbit_policy.spec.schema import SpecError

PACKAGED = "packaged"
"""A ``gait_library.source`` naming the library shipped in the package."""


def packaged_spec_dir() -> Path:
    """Where the shipped controller specs live (``rabbit_policy/controllers``)."""
    return Path(str(files("rabbit_policy") / "controllers"))


def packaged_spec(kind: str) -> Path:
    """The shipped spec of controller ``kind`` (classic, recovery, learned)."""
    return packaged_spec_dir() / f"{kind}.yaml"


def file_sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def library_hash(directory: Path) -> str:
    """SHA-256 over the library's files (``*.json``: the gaits and ``interpolation.json``),
    by name and content, in name order."""
    digest = hashlib.sha256()
    paths = sorted(Path(directory).glob("*.json"))
    if not any(p.name != CALIBRATION_FILE for p in paths):
        raise SpecError(f"no gait files (*.json) in {directory}")
    for path in paths:
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def library_dir(source: str, base: Path) -> Path:
    """The directory a ``gait_library.source`` names (relative to the spec's directory ``base``)."""
    return packaged_gait_dir() if source == PACKAGED else (base / source).resolve()


def checked_library_dir(source: str, sha256: str, base: Path) -> Path:
    """The library directory, its hash checked; :class:`SpecError` with one line otherwise."""
    directory = library_dir(source, base)
    if not directory.is_dir():
        raise SpecError(f"gait_library.source {source!r}: no directory {directory}")
    found = library_hash(directory)
    if found != sha256:
        raise SpecError(f"gait_library {directory} has sha256 {found[:16]}..., the spec names {sha256[:16]}...: "
                        "the library changed since the spec was written")
    return directory


def weights_name(sha256: str, stem: str = "weights") -> str:
    """A weights file's name: ``<stem>-<first 12 hex digits of its hash>.npz``."""
    return f"{stem}-{sha256[:12]}.npz"


def weights_bytes(weights: list[np.ndarray], biases: list[np.ndarray]) -> bytes:
    """The layers (``layers.K.weight`` / ``layers.K.bias``, float32) as ``.npz`` bytes that
    depend on the arrays only (no time stamps), so the same weights give the same hash."""
    import io
    import zipfile

    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_STORED) as archive:  # fixed dates: reproducible bytes
        for k, (w, b) in enumerate(zip(weights, biases)):
            for part, array in (("weight", w), ("bias", b)):
                member = io.BytesIO()
                np.lib.format.write_array(member, np.ascontiguousarray(array, dtype=np.float32), allow_pickle=False)
                info = zipfile.ZipInfo(f"layers.{k}.{part}.npy", date_time=(1980, 1, 1, 0, 0, 0))
                archive.writestr(info, member.getvalue())
    return buffer.getvalue()


def weights_spec_of(weights: list[np.ndarray], biases: list[np.ndarray], stem: str = "weights") -> tuple[str, str]:
    """(file name, sha256) the layers would be saved under (:func:`save_weights`), nothing written."""
    sha = hashlib.sha256(weights_bytes(weights, biases)).hexdigest()
    return weights_name(sha, stem), sha


def save_weights(weights: list[np.ndarray], biases: list[np.ndarray], directory: Path,
                 stem: str = "weights") -> tuple[str, str]:
    """Write the layers as an ``.npz`` (:func:`weights_bytes`) in ``directory``, named by its
    hash; returns (file name, sha256)."""
    data = weights_bytes(weights, biases)
    sha = hashlib.sha256(data).hexdigest()
    name = weights_name(sha, stem)
    (Path(directory) / name).write_bytes(data)
    return name, sha


def load_weights(file: str, sha256: str, base: Path, layers: int) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The ``layers`` weight matrices and bias vectors of a weights file beside the spec, its
    hash checked; :class:`SpecError` with one line otherwise."""
    import io
    import zipfile

    path = (base / file).resolve()
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise SpecError(f"network.weights.file {file!r}: cannot read {path}: {exc.strerror or exc}") from None
    found = hashlib.sha256(data).hexdigest()
    if found != sha256:
        raise SpecError(f"network weights {path} have sha256 {found[:16]}..., the spec names {sha256[:16]}...")
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as archive:
            tensors = {name: archive[name] for name in archive.files}
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise SpecError(f"network weights {path} are not a weights file (.npz of arrays): {exc}") from None
    expected = {f"layers.{k}.{part}" for k in range(layers) for part in ("weight", "bias")}
    if set(tensors) != expected:
        raise SpecError(f"network weights {path} hold {sorted(tensors)}, the spec's architecture needs "
                        f"{sorted(expected)}")
    return ([tensors[f"layers.{k}.weight"] for k in range(layers)],
            [tensors[f"layers.{k}.bias"] for k in range(layers)])
