"""The standard benchmark pose graphs, fetched from SE-Sync's public ``data/`` folder (Rosen et
al. 2019, david-m-rosen/SE-Sync at a fixed commit) and checked against their SHA-256.

They go to ``download_dir()``: ``$POSEGRAPH_DATASETS``, or ``~/.cache/posegraph/datasets``
(under ``$XDG_CACHE_HOME`` where set). ``$POSEGRAPH_DATASETS_URL`` replaces the address the
files are fetched from (a mirror; ``file://`` addresses work too).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from pathlib import Path

from posegraph.io.atomic import atomic_path

DATASETS_ENV = "POSEGRAPH_DATASETS"
URL_ENV = "POSEGRAPH_DATASETS_URL"
SE_SYNC_URL = (
    "https://raw.githubusercontent.com/david-m-rosen/SE-Sync/"
    "9b631b6b82d8aa7d32ab846412ae1c070412b7b6/data/"
)

GRAPHS = {
    "ais2klinik.g2o": "e388ebd8523987c1004082d7eaeb5e6fb640b773d05ccebeef1ce1e8df64e1e7",
    "city10000.g2o": "df5988994339e990be198a36e7f640e31a5a1b26df3ed400363fafc49d5ca630",
    "CSAIL.g2o": "66d99ac857a9849d814d214a9ebd0d4876d5d40f0a37be9330c1ff6e6e9daaa6",
    "cubicle.g2o": "f7781d485383cec86d47d7650970132c36d6f3a1f4e5d62a49b7f8245c0a6465",
    "intel.g2o": "3e0724c048e0ba524be9dd268a8b78e19a2497043143584cbb61310638b15c4b",
    "kitti_00.g2o": "8a9807f604852a44254910100917918def94d7357748c633e1fd7ce73dd17468",
    "kitti_02.g2o": "2a77a2c27e2e3afcde6f189c132ca6a228afd1a73d8509cfbcac2201555dd3e7",
    "kitti_05.g2o": "05a85336eaaae8f7d22226d38a1829f305ac49ad1a71c488bcd71672ca0ff9e3",
    "manhattan.g2o": "6ae8d30971720c1af24a00c4b2dd5c5ddafbbbe488bfc771145c47decbffb248",
    "MIT.g2o": "e5922be0d0689c7a5bc04c58adf3a8e697e240bdd7691cc4218470eaf92956eb",
    "parking-garage.g2o": "3ac0a31bfb601d7455d451e2546655cb5dececf51a7823f57c8a7e0fe1ca6527",
    "smallGrid3D.g2o": "9ea56c2ad1ebcc322560eb2f8d83cb3a60f99e2e2acc35e097b1162cdbafd649",
    "sphere2500.g2o": "104ab57593394f24351d9f692f3b923f8b98fff1eb638c64356cf5049e06cf3c",
    "sphere_bignoise_vertex3.g2o": "484aa1999084d353d83725ba1d992cb709ad3a7e6c396155cc8e87a059c645db",
    "tinyGrid3D.g2o": "c341eb0d09f7556b337be5a62b9354384885333a25fa718fd699fafb19620493",
    "torus3D.g2o": "1ef8831023b372188d33ca63ce0da079d51df89364df71f2bce1c5c7c69ed5ec",
}
"""File name → SHA-256 of SE-Sync's benchmark graphs (its grid3D and rim, stored with Git LFS,
are not among them)."""


class DownloadError(ValueError):
    """A file that could not be fetched, or whose contents are not the ones expected."""


def download_dir() -> Path:
    """Where ``download`` puts the graphs (module docstring)."""
    if os.environ.get(DATASETS_ENV):
        return Path(os.environ[DATASETS_ENV])
    cache = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(cache) / "posegraph" / "datasets"


def graph_name(name: str) -> str:
    """The file name of a benchmark graph given with or without ``.g2o`` (any case)."""
    by_stem = {Path(file).stem.lower(): file for file in GRAPHS}
    stem = Path(name).stem.lower() if name.lower().endswith(".g2o") else name.lower()
    if stem not in by_stem:
        known = ", ".join(sorted(Path(file).stem for file in GRAPHS))
        raise DownloadError(f"unknown benchmark graph {name!r} (known: {known})")
    return by_stem[stem]


def _sha256(stream) -> str:
    digest = hashlib.sha256()
    for block in iter(lambda: stream.read(1 << 20), b""):
        digest.update(block)
    return digest.hexdigest()


def sha256(path: Path) -> str:
    with open(path, "rb") as stream:
        return _sha256(stream)


def is_present(file: str, folder: Path) -> bool:
    """Whether ``folder`` holds ``file`` with the expected contents."""
    path = folder / file
    return path.is_file() and sha256(path) == GRAPHS[file]


def download(file: str, folder: Path | None = None) -> tuple[Path, bool]:
    """Fetch one graph (by file name: ``graph_name``) into ``folder`` (``download_dir()``),
    unless it is there already; returns its path and whether it was fetched. The file appears
    only once its SHA-256 is the expected one."""
    import urllib.request  # on use: every command imports this module, few fetch

    folder = download_dir() if folder is None else folder
    path = folder / file
    if is_present(file, folder):
        return path, False
    folder.mkdir(parents=True, exist_ok=True)
    url = (os.environ.get(URL_ENV) or SE_SYNC_URL).rstrip("/") + "/" + file
    with tempfile.TemporaryFile() as buffer:
        try:
            with urllib.request.urlopen(url, timeout=60) as response:
                shutil.copyfileobj(response, buffer)
        except OSError as error:
            raise DownloadError(f"{url}: cannot fetch ({error})") from None
        buffer.seek(0)
        digest = _sha256(buffer)
        if digest != GRAPHS[file]:
            raise DownloadError(
                f"{url}: SHA-256 {digest} is not the expected {GRAPHS[file]}; nothing written"
            )
        buffer.seek(0)
        with atomic_path(str(path)) as temporary, open(temporary, "wb") as target:
            shutil.copyfileobj(buffer, target)
    return path, True
