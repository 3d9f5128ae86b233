"""Rollout videos for `dgz eval --video DIR`: a few episodes rendered offscreen with MuJoCo's renderer into MP4
(imageio-ffmpeg, whose wheel carries an ffmpeg binary) plus one contact-sheet PNG.

Offscreen rendering needs an OpenGL backend. Without a display, :func:`prepare_gl` picks EGL (``MUJOCO_GL=egl``,
Debian: ``libegl1 libgl1-mesa-dri``, software rendering works without a GPU) before MuJoCo is imported;
``MUJOCO_GL=osmesa`` (``libosmesa6``) also works. :func:`gl_problem` tells, in one line, why rendering is not
possible here, so the caller can skip the videos and still evaluate.

The episodes are rendered in an env of their own (one slot per hand, its first object), seeded as the
evaluation is, so the first video of a hand is that env's trial 0 at ``--seed``.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

WIDTH, HEIGHT = 320, 240  # multiples of 16 (H.264 macro blocks)
STRIDE = 2  # render every 2nd control step: 10 frames/s at 20 Hz, played in real time
SHEET_COLUMNS = 6
OBJECT_RGBA = (0.85, 0.55, 0.2, 1.0)  # display only (geom_rgba plays no part in the physics)


def prepare_gl() -> str:
    """Choose the offscreen backend before MuJoCo is imported: the user's ``MUJOCO_GL``, else EGL when there is
    no display (GLFW needs one). Returns the backend in use."""
    if not os.environ.get("MUJOCO_GL") and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ["MUJOCO_GL"] = "egl"
    return os.environ.get("MUJOCO_GL", "glfw")


def gl_problem() -> str | None:
    """None when an offscreen renderer can be created here, else one line saying why not."""
    backend = os.environ.get("MUJOCO_GL", "glfw")
    try:
        import mujoco

        model = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom size='.1'/></worldbody></mujoco>")
        with mujoco.Renderer(model, 16, 16) as r:
            r.update_scene(mujoco.MjData(model))
            r.render()
    except Exception as exc:  # noqa: BLE001 (GL failures come as many types; one line says which)
        text = " ".join(str(exc).split()).split(". ")[0][:140] or type(exc).__name__
        return (f"no OpenGL backend for offscreen rendering (MUJOCO_GL={backend}: {text}); install Debian's "
                "libegl1 libgl1-mesa-dri (MUJOCO_GL=egl) or libosmesa6 (MUJOCO_GL=osmesa)")
    try:
        import imageio_ffmpeg

        imageio_ffmpeg.get_ffmpeg_exe()
    except Exception as exc:  # noqa: BLE001
        return f"no ffmpeg for MP4 ({type(exc).__name__}); pip install imageio-ffmpeg"
    return None


@dataclass
class Episode:
    hand: str
    object: str
    index: int
    frames: list[np.ndarray] = field(default_factory=list)
    success: bool | None = None


def _camera(slot):
    import mujoco

    cam = mujoco.MjvCamera()
    p = slot.data.xpos[slot.idx.object_body]
    cam.lookat[:] = [p[0], p[1], p[2] + 0.28]  # the object's start, raised: the 0.5 m lift stays in the picture
    cam.distance, cam.azimuth, cam.elevation = 1.0, 135.0, -12.0
    return cam


def rollouts(pairs: list, make_policy: Callable, episodes: int, cfg, seed: int = 0, asset_root: str | None = None,
             progress: Callable[[int, int], None] | None = None) -> list[Episode]:
    """``episodes`` episodes of every (hand, object) pair in ``pairs``, rendered at WIDTH×HEIGHT."""
    import mujoco

    from dgz_cli.sim.evaluate import make_env

    env = make_env(pairs, cfg, seed=seed, asset_root=asset_root, threads=1)  # eval's protocol, training-only options off
    try:
        policy = make_policy(env)
        obs = env.reset(seed)
        policy.reset(None)
        option = mujoco.MjvOption()
        option.geomgroup[:] = 1  # collision geometry is all the env compiles (visuals are discarded)
        for s in env.slots:  # the object in orange, so it stands out from the grey hand and table
            s.model.geom_rgba[s.model.geom_bodyid == s.idx.object_body] = OBJECT_RGBA
        renderers = [mujoco.Renderer(s.model, HEIGHT, WIDTH) for s in env.slots]
        for r in renderers:  # software GL (no GPU): shadows and reflections cost ~10x the frame time
            for flag in (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION):
                r.scene.flags[flag] = 0
        current = [Episode(s.spec.name, s.obj.name, 0) for s in env.slots]
        cams = [_camera(s) for s in env.slots]
        done: list[Episode] = []
        total, step = episodes * env.B, 0
        while len(done) < total:
            obs, _, _, _, info = env.step(policy.act(obs))
            step += 1
            finished = np.zeros(env.B, bool)
            for b, ep in info["episode"].items():
                finished[b] = True
                if current[b].index < episodes:
                    current[b].success = bool(ep["success"])
                    done.append(current[b])
                    if progress is not None:
                        progress(len(done), total)
                current[b] = Episode(env.slots[b].spec.name, env.slots[b].obj.name, current[b].index + 1)
                cams[b] = _camera(env.slots[b])
            if finished.any():
                policy.reset(finished)
            if step % STRIDE == 0:
                for b, s in enumerate(env.slots):
                    if current[b].index < episodes and not finished[b]:
                        renderers[b].update_scene(s.data, camera=cams[b], scene_option=option)
                        current[b].frames.append(renderers[b].render().copy())
        for r in renderers:
            r.close()
    finally:
        env.close()
    return sorted(done, key=lambda e: (e.hand, e.object, e.index))


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


def write_mp4(path: Path, frames: list[np.ndarray], fps: float) -> None:
    """Frames → H.264 MP4, written to a temporary name in the same folder and renamed (atomic)."""
    import imageio_ffmpeg

    from dgz_cli.spec.errors import DgzError

    tmp = path.with_name(f".{path.name}.tmp.mp4")
    try:
        writer = imageio_ffmpeg.write_frames(str(tmp), (WIDTH, HEIGHT), fps=fps, codec="libx264", pix_fmt_out="yuv420p",
                                             quality=6, macro_block_size=16, ffmpeg_log_level="error")
        writer.send(None)
        for f in frames:
            writer.send(np.ascontiguousarray(f))
        writer.close()
        os.replace(tmp, path)
    except (OSError, RuntimeError) as exc:
        tmp.unlink(missing_ok=True)
        raise DgzError(f"cannot write {path}: {' '.join(str(exc).split())[:160]}", "check --video DIR") from None


def contact_sheet(episodes: list[Episode]) -> bytes:
    """One row per episode, SHEET_COLUMNS frames spread over it, labelled hand / object / episode / outcome."""
    import io

    from PIL import Image, ImageDraw

    label_h = 18
    sheet = Image.new("RGB", (SHEET_COLUMNS * WIDTH, len(episodes) * (HEIGHT + label_h)), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    for row, ep in enumerate(episodes):
        y = row * (HEIGHT + label_h)
        outcome = "success" if ep.success else "failure"
        draw.text((4, y + 3), f"{ep.hand} / {ep.object} / episode {ep.index}: {outcome} "
                              f"({len(ep.frames)} frames, left to right over the episode)", fill=(0, 0, 0))
        if not ep.frames:
            continue
        picks = np.linspace(0, len(ep.frames) - 1, SHEET_COLUMNS).round().astype(int)
        for col, k in enumerate(picks):
            sheet.paste(Image.fromarray(ep.frames[k]), (col * WIDTH, y + label_h))
    buf = io.BytesIO()
    sheet.save(buf, format="PNG")
    return buf.getvalue()


def write_videos(episodes: list[Episode], out_dir: Path, control_hz: float) -> list[Path]:
    """``<hand>_<object>_ep<k>.mp4`` per episode and ``contact_sheet.png`` in ``out_dir``."""
    from dgz_cli.spec.io import atomic_write_bytes

    written = []
    for ep in episodes:
        path = out_dir / f"{_safe(ep.hand)}_{_safe(ep.object)}_ep{ep.index}.mp4"
        write_mp4(path, ep.frames, control_hz / STRIDE)
        written.append(path)
    sheet = out_dir / "contact_sheet.png"
    atomic_write_bytes(sheet, contact_sheet(episodes))
    written.append(sheet)
    return written
