"""Public recorded data sets the project is tested and benchmarked on.

The data are not part of the repository. They live in one folder, the *data
root*: ``$GSLAM_DATA`` if set, else ``../shared/data`` beside the project
root. Each set keeps the layout of its public source:

=============  ==========================================================  =================  ==============================
folder         original public source                                      licence            reader (``input.format``)
=============  ==========================================================  =================  ==============================
``carmen/``    Radish / Freiburg "corrected" CARMEN logs, as collected     none stated;       ``carmen`` (:mod:`slam.readers.carmen`)
               in https://github.com/acschaefer/ple (``data/carmen/``)      research use
``broad/``     BROAD benchmark, https://github.com/dlaidig/broad            CC BY 4.0          ``broad`` (:mod:`slam.readers.broad`)
               (``data_mat/*.mat``, ``trials.json``)
``librsf/``    libRSF data sets, https://github.com/TUC-ProAut/libRSF       CC BY-NC-SA 4.0    ``librsf`` (:mod:`slam.readers.librsf`)
               (``datasets/SLAM/Corridor_*``, ``datasets/Indoor_UWB/``)    / CC BY-SA 4.0
``rosbag/``    ``test/test1.bag`` (here ``test1_husky_2015.bag``) of         BSD / Apache       ``rosbag`` (:mod:`slam.readers.rosbag`)
               https://github.com/cra-ros-pkg/robot_localization
=============  ==========================================================  =================  ==============================

:data:`CHECKSUMS` holds the SHA-256 of every file as the project uses it, so
a local copy can be checked with ``python scripts/datasets.py verify``.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from enum import Enum
from pathlib import Path

from slam.errors import GslamError

DATA_ENV = "GSLAM_DATA"


def data_root() -> Path:
    """The folder holding the recorded data sets: ``$GSLAM_DATA`` if set (a
    relative path from the working folder, ``~`` expanded), else
    ``shared/data`` beside the project folder (``../shared/data`` relative
    to the project root). Raises :class:`GslamError` for a ``~user`` that
    names no user."""
    env = os.environ.get(DATA_ENV)
    if env:
        try:
            return Path(env).expanduser().absolute()
        except RuntimeError:  # ~user of no user, or no home at all
            raise GslamError(f"{DATA_ENV}={env!r}: cannot expand '~' (no such user or no home folder); "
                             "expected the folder holding the data sets") from None
    return Path(__file__).resolve().parents[2].parent / "shared" / "data"


@dataclass(frozen=True)
class Dataset:
    """One public data set: its folder under the data root, where it comes
    from and under which licence, and the reader format that reads it."""

    folder: str
    source: str
    licence: str
    reader: str
    description: str


DATASETS: tuple[Dataset, ...] = (
    Dataset(
        "carmen",
        "https://github.com/acschaefer/ple (data/carmen/), originally the Radish repository "
        "and the Freiburg SLAM benchmark (Kümmerle et al., Autonomous Robots 2009)",
        "no explicit licence; widely used for research",
        "carmen",
        "2D laser + raw wheel odometry, with the SLAM-corrected poses as reference",
    ),
    Dataset(
        "broad",
        "https://github.com/dlaidig/broad (data_mat/; Laidig et al., BROAD, 2021)",
        "CC BY 4.0",
        "broad",
        "hand-held IMU (gyro, accelerometer, magnetometer) with optical motion-capture truth; "
        "undisturbed and magnetically disturbed trials",
    ),
    Dataset(
        "librsf",
        "https://github.com/TUC-ProAut/libRSF (datasets/SLAM/Corridor_*, datasets/Indoor_UWB/); "
        "TUC SLAM data set, Neubert, Schubert & Protzel, RA-L 2019",
        "CC BY-NC-SA 4.0 (SLAM sets), CC BY-SA 4.0 (Indoor_UWB)",
        "librsf",
        "wheel speed + yaw rate at 10 Hz with ground-truth positions and headings",
    ),
    Dataset(
        "rosbag",
        "https://github.com/cra-ros-pkg/robot_localization (test/test1.bag)",
        "BSD / Apache (the project's licence)",
        "rosbag",
        "Clearpath Husky outdoors: IMU, wheel odometry, GPS; no laser, no ground truth",
    ),
)

# SHA-256 of every file of the data root, keyed by its path below the root.
CHECKSUMS: dict[str, str] = {
    "carmen/aces-corrected.log.gz": "5434d44384166250608a64d3a8c32de84512f82c46cb60a2657f138592024569",
    "carmen/belgioioso-corrected.log.gz": "a130e3e6d9e5ec5e6a7f94cbb5cb6bca2df2626c7ed6bebb7b7a282253b10f6e",
    "carmen/csail-corrected.log.gz": "a98de24fc319651f231f9a8625b78bf1972312b86f7b00d2ddc979c4ac92ae2d",
    "carmen/fhw-corrected.log.gz": "4233abbfbc15baaddc730aceb3482dc660b25c9d5757005fff97a3fe083595b8",
    "carmen/freiburg-079-corrected.log.gz": "0631d30baf4b9d1d209af47da9096e876e1b4cb3d5a2d68ef9c39c5a2360a466",
    "carmen/freiburg-101-corrected.log.gz": "7792de88bcb050f8edba92914aea75e8ec2fb73b483c01903bd2753aa655e982",
    "carmen/infinite-corridor-corrected.log.gz": "6a63c51eb97aa4e720fe207e91f926c283f77b4c534903983f9c5a6cbed6ebc4",
    "carmen/intel-corrected.log.gz": "71bef16e9926506cf7417995ef35ace09dbd5de067fd042a3aab85188b5480dc",
    "carmen/orebro-corrected.log.gz": "39a189c64489b84996669bc484d6bd6864f8733029a280a0e549a0adaae08a82",
    "carmen/seattle-corrected.log.gz": "5719198036b788d78a877ca04efdbfb07c2518508310f51d49c198bf1956bb4b",
    "broad/01_undisturbed_slow_rotation_A.mat": "ad2cec0390a279953084e1de12dfd8d542af55e4ea187e68e8ebb7c316ecb96b",
    "broad/02_undisturbed_slow_rotation_B.mat": "2ab69f86aab5fcc018399068baaabc725bb4b53862aefbef70eaf0256da1930a",
    "broad/04_undisturbed_slow_rotation_with_breaks_A.mat": "e414276dc54fd01337a9d26b1c635900e46218f4859f1f011f44dd9994df24e0",
    "broad/06_undisturbed_fast_rotation_A.mat": "61cb32774b40c33d16a172dbe06503b4a3cb0b2d3e9b8eae0df66c313506a8e2",
    "broad/08_undisturbed_fast_rotation_with_breaks_A.mat": "18f754d90fc4442dd9b01e116bf2b763d71517098702d77096080657a9460fd3",
    "broad/10_undisturbed_slow_translation_A.mat": "eee6293f1d0aaf8d0ac025b873667f6f7697acad318057f4fd6a801fb31c93c1",
    "broad/15_undisturbed_fast_translation_A.mat": "4290740d09dc3e055dd3cc939d083fa55321a9c90c0cb0aa3a6ffc26c4350951",
    "broad/24_disturbed_tapping_A.mat": "1246fed1680a882a5f4d0dc2ae16e2db9dc90281fbaf1d486c84db1f27db51fa",
    "broad/26_disturbed_phone_vibration_A.mat": "545dda7c8b00548cfa476d53fa7e520bfae98f40ad2dac1b5686f5fda5117735",
    "broad/28_disturbed_stationary_magnet_A.mat": "a909fb0b89ff454328cdb1151e6b796082b748a4cb5d6b00986a221649ccff42",
    "broad/29_disturbed_stationary_magnet_B.mat": "0ce63a5f7255e517de271b9cb4349be84ec2ad3c1151c34b16b29637e3a05762",
    "broad/32_disturbed_attached_magnet_1cm.mat": "1919d236f89947247ccae26e7ad04a543da47686ea3fab6ad6855b7e0402c4f3",
    "broad/33_disturbed_attached_magnet_2cm.mat": "23681a20515ca56573e81a56f5d8841cb4f55fafc98cac7624d0cac28b76e441",
    "broad/trials.json": "9f4a680062fd5b6b500653fe7f8e7dd774dedbf4fe573210328ec8d0d263c2fd",
    "librsf/Corridor_GT.txt": "455ea2aa3fd21b56345f0c61b69fad4d5021364e9bc4d4e92a493fe94edd194f",
    "librsf/Corridor_Input.txt": "925e884b1081c7dbd72f15b0eeac241ae5743ad33408dcbec4bbe35ea6f99432",
    "librsf/Indoor_UWB/Indoor_UWB_GT.txt": "49057cc9fdf14e464bca8cfab9894dddc1668c53e08878e30d6d1040e3f9f2a2",
    "librsf/Indoor_UWB/Indoor_UWB_Input.txt": "d0a1ac1e96f508a8fe7a0f40d4152d005ecd3e708403a521da93d4377e3c3b77",
    "rosbag/test1_husky_2015.bag": "fd759aa942a3ef549412ff724d15e7280a347a366996a012cf9079329ec28f4a",
}


class FileStatus(Enum):
    """Outcome of checking one local file against :data:`CHECKSUMS`."""

    OK = "ok"
    MISSING = "missing"
    MISMATCH = "mismatch"


def sha256_file(path: Path, chunk_bytes: int = 1 << 20) -> str:
    """Hex SHA-256 of a file, read in chunks."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(chunk_bytes), b""):
            digest.update(chunk)
    return digest.hexdigest()


def verify(root: Path | None = None) -> dict[str, FileStatus]:
    """Check every file of :data:`CHECKSUMS` under ``root`` (default
    :func:`data_root`); returns the status per relative path."""
    root = data_root() if root is None else Path(root)
    status: dict[str, FileStatus] = {}
    for rel, expected in CHECKSUMS.items():
        path = root / rel
        if not path.is_file():
            status[rel] = FileStatus.MISSING
        else:
            status[rel] = FileStatus.OK if sha256_file(path) == expected else FileStatus.MISMATCH
    return status
