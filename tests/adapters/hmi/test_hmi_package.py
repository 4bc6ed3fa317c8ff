"""`pip install .` serves the HMI too: the wheel carries every file of hmi/ and the trend library
npm installed (uPlot), and an installed softplc (not the clone) finds and serves them."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import textwrap
import zipfile
from pathlib import Path

import pytest
from hmi_support import REPO

from softplc.adapters.hmi.assets import AssetsNotFound, find_assets

pytestmark = pytest.mark.slow

SERVE = textwrap.dedent("""
    import asyncio, sys, urllib.request
    import softplc
    from softplc.core.clock import RealClock
    from softplc.config import parse_config
    from softplc.adapters.hmi.server import HmiServer
    from softplc.adapters.hmi.settings import HmiSettings
    from softplc.app.runtime import Runtime

    async def main():
        config = parse_config("version: 1\\ntags: {x: {type: int16}}\\n", sys.argv[1] + "/tagdb.yaml")
        runtime = Runtime(config, RealClock(), state_dir=__import__("pathlib").Path(sys.argv[1]))
        hmi = HmiServer(config, HmiSettings(port=0))
        runtime.add_adapter(hmi)
        await runtime.start()
        try:
            for path in ("", "static/js/main.js", "static/js/pages/overview.js", "static/css/hmi.css",
                         "vendor/uplot/dist/uPlot.esm.js", "vendor/uplot/dist/uPlot.min.css"):
                body = await asyncio.to_thread(lambda: urllib.request.urlopen(hmi.url + path, timeout=5).read())
                print(path or "/", len(body))
            print("package", softplc.__file__)
            print("assets", hmi.assets)
        finally:
            await runtime.stop()

    asyncio.run(main())
""")


VENDORED = {"node_modules/uplot/dist/uPlot.esm.js", "node_modules/uplot/dist/uPlot.min.css", "node_modules/uplot/LICENSE",
            "node_modules/uplot/package.json"}  # what the pages load of the libraries npm installed, and their licence


def front_end_files() -> set[str]:
    root = REPO / "hmi"
    return {str(path.relative_to(root)) for path in root.rglob("*") if path.is_file() and "node_modules" not in path.parts}


def vendored_files() -> set[str]:
    """The vendored files as bootstrap installed them (`npm ci`); the tests need them there."""
    missing = [name for name in VENDORED if not (REPO / "hmi" / name).is_file()]
    if missing:
        pytest.fail(f"hmi/node_modules lacks {missing}: run scripts/bootstrap.sh (npm ci in hmi/)")
    return VENDORED


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    # Build from a copy: setuptools writes build/ and egg-info next to the sources.
    source = tmp_path_factory.mktemp("source")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO / name, source / name)
    shutil.copytree(REPO / "softplc", source / "softplc", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(REPO / "hmi", source / "hmi", ignore=shutil.ignore_patterns("node_modules"))
    for name in vendored_files():  # as npm ci leaves them (only what is shipped: the copy stays small)
        (source / "hmi" / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(REPO / "hmi" / name, source / "hmi" / name)
    out = tmp_path_factory.mktemp("wheel")
    result = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "--disable-pip-version-check", "-w", str(out), str(source)],
                            capture_output=True, text=True, timeout=300)
    if result.returncode != 0:
        pytest.fail(f"building the wheel failed:\n{result.stdout}\n{result.stderr}")
    (built,) = out.glob("softplc-*.whl")
    return built


def test_the_wheel_carries_every_file_of_the_front_end(wheel: Path) -> None:
    prefix = "softplc-0.1.0.data/data/share/softplc/hmi/"
    with zipfile.ZipFile(wheel) as archive:
        shipped = {name[len(prefix):] for name in archive.namelist() if name.startswith(prefix)}
    missing = (front_end_files() | vendored_files()) - shipped
    assert not missing, f"add these to [tool.setuptools.data-files] in pyproject.toml: {sorted(missing)}"


def test_a_wheel_built_without_npm_ci_still_builds(tmp_path: Path) -> None:
    """Without hmi/node_modules the wheel builds all the same (the HMI then says the trend library is missing)."""
    source = tmp_path / "source"
    source.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO / name, source / name)
    shutil.copytree(REPO / "softplc", source / "softplc", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(REPO / "hmi", source / "hmi", ignore=shutil.ignore_patterns("node_modules"))
    result = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "--disable-pip-version-check", "-w", str(tmp_path),
                             str(source)], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    (built,) = tmp_path.glob("softplc-*.whl")
    with zipfile.ZipFile(built) as archive:
        assert not [name for name in archive.namelist() if "node_modules" in name]


def test_an_installed_softplc_serves_the_hmi_from_its_environment(wheel: Path, tmp_path: Path) -> None:
    environment = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(environment)], check=True, timeout=120)
    python = environment / "bin" / "python"
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--quiet", "--disable-pip-version-check",
                    str(wheel)], check=True, timeout=300, capture_output=True)
    # The dependencies come from this environment's site-packages (on the path, not a site
    # directory: its .pth files, among them the editable clone's, are not read).
    env = {**os.environ, "PYTHONPATH": sysconfig.get_paths()["purelib"]}
    env.pop("SOFTPLC_HMI_DIR", None)
    result = subprocess.run([str(python), "-c", SERVE, str(tmp_path)], capture_output=True, text=True, timeout=120, env=env, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    lines = dict(line.split(" ", 1) for line in result.stdout.splitlines())
    assert str(environment) in lines["package"], lines  # the installed package, not the clone
    assert lines["assets"] == str(environment / "share" / "softplc" / "hmi")
    assert int(lines["/"]) > 500 and int(lines["static/js/main.js"]) > 1000
    assert int(lines["vendor/uplot/dist/uPlot.esm.js"]) > 100_000  # the trend library is served by an installed runtime


def test_a_folder_that_is_not_ours_is_not_taken_for_the_front_end(tmp_path: Path) -> None:
    (tmp_path / "index.html").write_text("<html></html>")
    with pytest.raises(AssetsNotFound, match="reinstall softplc or set SOFTPLC_HMI_DIR"):
        find_assets([tmp_path])
    assert find_assets([tmp_path, REPO / "hmi"]) == REPO / "hmi"
