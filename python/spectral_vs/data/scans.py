"""Where the real scans are: the folder of the shared data (:func:`data_dir`) and the
organized Kinect scans the view pairs are cut out of (:data:`SCANS`, :func:`scan_path`)."""

from __future__ import annotations

import os
from pathlib import Path

#: The organized Kinect scans (640 x 480) of ``$SPECTRAL_VS_DATA`` used for view pairs:
#: name -> file. A table top with clutter about 1 m away (0.5-2.1 m deep), and a room with
#: five people (1.8-9.8 m deep).
SCANS: dict[str, str] = {
    "table": "milk_cartoon_all_small_clorox.pcd",
    "room": "five_people.pcd",
}


def data_dir(data: str | os.PathLike[str] | None = None) -> Path:
    """Folder of the real scans: ``data`` if given, else ``$SPECTRAL_VS_DATA``, else
    ``../shared/data`` (relative to the working directory)."""
    if data is not None:
        return Path(data)
    return Path(os.environ.get("SPECTRAL_VS_DATA", "../shared/data"))


def scan_path(name: str, data: str | os.PathLike[str] | None = None) -> Path:
    """Path of the scan ``name`` (a key of :data:`SCANS`) in :func:`data_dir`.

    Raises
    ------
    ValueError
        If ``name`` is not a key of :data:`SCANS`.
    """
    if name not in SCANS:
        raise ValueError(f"name must be one of {sorted(SCANS)}, got {name!r}")
    return data_dir(data) / SCANS[name]
