"""A point cloud file rewritten by another process while it is read (a camera pipeline
writing frames while a viewer loads them): the reader gets a whole cloud or a clear
ValueError, never a signal. PCL memory-maps a binary PCD, and reading past the end of a
file truncated under the mapping raised SIGBUS within seconds (docs/reliability.md); the
reader now loads a private copy. The reader runs in its own process so that a signal
fails this test instead of ending the test run."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest

import spectral_vs as svs

POINTS = 20_000
SECONDS = 3.0


@pytest.mark.parametrize("encoding", ["binary", "binary_compressed", "ascii"])
def test_a_pcd_rewritten_while_read_loads_whole_or_raises(tmp_path, encoding):
    rng = np.random.default_rng(0)
    cloud = svs.PointCloud(rng.uniform(-1, 1, (POINTS, 3)))
    source = tmp_path / "frame.pcd"
    svs.save_cloud(str(source), cloud, encoding)
    whole = source.read_bytes()
    target = tmp_path / "live.pcd"
    target.write_bytes(whole)
    # The writer truncates the file and writes it back, over and over.
    writer = subprocess.Popen(
        [
            sys.executable,
            "-c",
            textwrap.dedent(
                f"""
                import time
                data = open({str(source)!r}, "rb").read()
                end = time.monotonic() + {SECONDS + 2.0}
                while time.monotonic() < end:
                    with open({str(target)!r}, "r+b") as f:
                        f.truncate(len(data) // 3)
                        f.flush()
                        f.seek(0)
                        f.write(data)
                """
            ),
        ]
    )
    reader = textwrap.dedent(
        f"""
        import time
        import spectral_vs as svs
        whole = refused = 0
        end = time.monotonic() + {SECONDS}
        while time.monotonic() < end:
            try:
                cloud = svs.load_cloud({str(target)!r})
            except ValueError:
                refused += 1
                continue
            assert len(cloud) == {POINTS}, len(cloud)
            whole += 1
        print(whole, refused)
        """
    )
    try:
        result = subprocess.run(
            [sys.executable, "-c", reader], capture_output=True, text=True, timeout=60
        )
    finally:
        writer.kill()
        writer.wait()
    assert result.returncode == 0, (result.returncode, result.stderr[-2000:])
    whole, refused = map(int, result.stdout.split())
    assert whole + refused > 10
