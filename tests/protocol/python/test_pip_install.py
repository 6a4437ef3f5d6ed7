"""`pip install ./client/python` works offline: into a fresh venv that sees the system's
packages (python3 -m venv --system-site-packages), with --no-index --no-build-isolation so
that nothing is fetched, and the installed package imports and decodes a frame.

Needs Debian's python3-venv, python3-setuptools and python3-wheel (deploy/install.sh).
Takes about 10 s: building the wheel is most of it."""

import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
PACKAGE = os.environ.get("VOLCAST_PYTHON_PACKAGE",
                         os.path.join(HERE, "..", "..", "..", "client", "python"))

MISSING = [name for name, module in (("python3-venv", "ensurepip"),
                                      ("python3-setuptools", "setuptools"),
                                      ("python3-wheel", "wheel"))
           if importlib.util.find_spec(module) is None]

# Run by the venv's python, outside the source tree and without PYTHONPATH: it must find the
# installed copy, typed, and usable.
CHECK = """
import os, sys, volcast
where = os.path.dirname(volcast.__file__)
assert where.startswith(sys.prefix), f"imported {where}, not the venv's copy under {sys.prefix}"
assert os.path.exists(os.path.join(where, "py.typed")), "py.typed is not installed"
header = {"seq": 1, "level": 0, "width": 1, "height": 1, "codec": "png", "render_ms": 0,
          "encode_ms": 0, "final": True}
frame = volcast.decode_frame(volcast.encode_frame(header, b"x"))
assert (frame.seq, frame.image) == (1, b"x"), frame
print(volcast.__version__, where)
"""


@unittest.skipIf(MISSING, f"not installed: {' '.join(MISSING)} (in deploy/install.sh)")
class PipInstall(unittest.TestCase):
    def run_checked(self, command, **kwargs):
        result = subprocess.run(command, capture_output=True, text=True, timeout=240, **kwargs)
        self.assertEqual(result.returncode, 0, f"{' '.join(command)} failed:\n{result.stdout}\n{result.stderr}")
        return result.stdout

    def test_installs_offline_into_a_venv_and_imports(self):
        with tempfile.TemporaryDirectory(prefix="volcast-pip-") as tmp:
            # A copy, so that the build's build/ and egg-info stay out of the source tree.
            source = os.path.join(tmp, "python")
            shutil.copytree(PACKAGE, source, ignore=shutil.ignore_patterns(
                "build", "*.egg-info", "__pycache__"))
            venv = os.path.join(tmp, "venv")
            self.run_checked([sys.executable, "-m", "venv", "--system-site-packages", venv])
            python = os.path.join(venv, "bin", "python")
            env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
            self.run_checked([python, "-m", "pip", "install", "--no-index", "--no-build-isolation",
                              "--no-cache-dir", "--disable-pip-version-check", source], env=env, cwd=tmp)
            out = self.run_checked([python, "-c", CHECK], env=env, cwd=tmp)
            self.assertTrue(out.startswith("0.1.0 "), f"the installed package says: {out!r}")


if __name__ == "__main__":
    unittest.main()
