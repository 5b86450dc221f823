"""numba's cache is keyed by the compiled sources: a kernel that compiles another file's law is
never loaded from a cache made before that law changed."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

from common import numba_cache

ROOT = Path(__file__).resolve().parent.parent


def test_numba_caches_in_this_versions_folder():
    assert os.environ["NUMBA_CACHE_DIR"] == str(numba_cache.CACHE_FOLDER)
    assert numba_cache.CACHE_FOLDER.parent == numba_cache.drivestack_cache() / "numba"
    assert numba_cache.CACHE_FOLDER.name == numba_cache.sources_key(ROOT)


def test_editing_a_law_in_one_file_keys_a_new_cache_and_other_edits_do_not(tmp_path):
    for package in numba_cache.PACKAGES:
        shutil.copytree(ROOT / package, tmp_path / package, ignore=shutil.ignore_patterns("__pycache__"))
    before = numba_cache.sources_key(tmp_path)
    law = tmp_path / "controllers" / "pid.py"
    law.write_text(law.read_text().replace("terms.ki * error * dt", "terms.ki * dt * error"))
    edited = numba_cache.sources_key(tmp_path)
    assert edited != before
    config = tmp_path / "controllers" / "config.py"
    assert b"numba" not in config.read_bytes()
    config.write_text(config.read_text() + "\n")
    assert numba_cache.sources_key(tmp_path) == edited


def test_a_process_keys_its_cache_under_drivestack_cache(tmp_path):
    environment = {**os.environ, "DRIVESTACK_CACHE": str(tmp_path)}
    environment.pop("NUMBA_CACHE_DIR", None)
    shown = subprocess.run(
        [sys.executable, "-c", "import controllers.pid, numba.core.config as c; print(c.CACHE_DIR)"],
        capture_output=True, text=True, check=True, env=environment, cwd=ROOT,
    ).stdout.strip()  # fmt: skip
    assert shown == str(tmp_path / "numba" / numba_cache.sources_key(ROOT))
