"""three-vrm, the reference VRM implementation, rendering a VRM at facepuppet's camera.

``three_vrm_render.mjs`` runs three.js + @pixiv/three-vrm (the repository's pinned node_modules)
in headless Chromium (playwright-core, Debian's /usr/bin/chromium, WebGL through SwiftShader) and
writes the picture with and without the MToon outlines. The scene is facepuppet's: the camera's
view and projection matrices, the background, the key light (``KEY_DIR`` of lighting.glsl, radiance
1: a DirectionalLight of intensity π) and the uniform environment of the metallic-roughness model
(``ENV_RADIANCE`` of character.glsl, a PMREM of a uniform colour); those two constants are read from
the shaders, so the reference follows them.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
from PIL import Image

from facepuppet.runtime.render.camera import Camera

REPO = Path(__file__).resolve().parents[2]
CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run",
                 "--use-angle=swiftshader", "--enable-unsafe-swiftshader"]


def missing() -> str | None:
    """Why three-vrm cannot run here (None when it can)."""
    if shutil.which("node") is None:
        return "node is not installed"
    if not CHROMIUM.exists():
        return f"{CHROMIUM} is not installed"
    for pkg in ("three", "@pixiv/three-vrm", "playwright-core"):
        if not (REPO / "node_modules" / pkg / "package.json").exists():
            return f"node_modules/{pkg} is missing (make setup runs npm ci)"
    return None


def shader_constant(name: str, file: str) -> tuple[float, ...]:
    """A ``const vec3 NAME = vec3(...)`` of a shader, as numbers (one number repeated for ``vec3(x)``)."""
    text = (REPO / "shaders" / file).read_text()
    m = re.search(rf"const vec3 {name} = vec3\(([^)]*)\)", text)
    values = tuple(float(x) for x in m.group(1).split(","))
    return values * 3 if len(values) == 1 else values


def render(vrm: Path, camera: Camera, width: int, height: int, background: tuple[float, float, float],
           out_prefix: Path, timeout: float = 240.0) -> tuple[np.ndarray, np.ndarray]:
    """three-vrm's picture of ``vrm`` at ``camera`` with and without outlines, (h, w, 3) uint8 each; the
    PNGs are kept at ``out_prefix``_on.png / _off.png."""
    key = np.asarray(shader_constant("KEY_DIR", "lighting.glsl"))
    config = {
        "vrm": str(Path(vrm).resolve()), "width": width, "height": height,
        "view": camera.view.astype(np.float64).T.ravel().tolist(),
        "projection": camera.projection.astype(np.float64).T.ravel().tolist(),
        "background": list(background), "key_dir": (key / np.linalg.norm(key)).tolist(),
        "env_radiance": shader_constant("ENV_RADIANCE", "character.glsl")[0],
        "out_prefix": str(out_prefix), "chromium": str(CHROMIUM),
    }
    # playwright-core gives the browser a fresh profile folder of its own (it refuses --user-data-dir)
    config["args"] = CHROMIUM_ARGS
    done = subprocess.run(["node", str(REPO / "tests" / "helpers" / "three_vrm_render.mjs")],
                          input=json.dumps(config), capture_output=True, text=True, timeout=timeout, cwd=REPO)
    if done.returncode != 0:
        raise RuntimeError(f"three-vrm render failed ({done.returncode}): {done.stderr[-2000:]}")
    return tuple(np.asarray(Image.open(f"{out_prefix}_{k}.png").convert("RGB")) for k in ("on", "off"))
