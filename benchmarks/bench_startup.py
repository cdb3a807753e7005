"""Benchmark: how long an experimenter and a participant wait for the app to start, in fresh processes.

* ``studyapp --help`` against a bare ``python -c "import numpy"`` (target: within 2x), and ``studyapp
  validate`` of the demo design, each a cold process, the three alternating over the same number of runs;
* the first trial frame of the demo, offscreen: from just before the process starts to the first frame of
  the first trial -- the three figures and the participant UI over them, as :class:`~studyapp.ui.app.StudyApp`
  draws a trial frame -- rendered at 1280x720 and read back, with the time of each step inside the process
  (target: 1.5 s), in the order of the participant window: imports, design, GL context, the UI library,
  the UI layer and a "Loading..." frame, trial media, renderer and scene, the frame itself (the results
  database and session rows, a few milliseconds, are left out). No frame waits for the audio output (the
  app takes it once open), but its process runs on the same cores meanwhile, so its cost is in the wall
  time, and its CPU time (the process is joined) in the CPU figure. The script runs as a file, as the ``studyapp`` console script does, and
  starts the audio output as ``studyapp run`` does (:class:`~studyapp.audio.playback.PendingClock`, before
  the design loads), so the output process and its cost are in the figure; with no sound server, a null
  PulseAudio sink is started for the benchmark (a participant's machine has a sound card). The design is
  loaded as a session start loads it (``reuse_check=True``): the full file check is skipped only because
  the ``validate`` runs of the same loop recorded it (:mod:`studyapp.study.design.validated`), as an
  experimenter validates before the first participant;
* the same on a machine where the app never ran: fresh, empty cache folders (``XDG_CACHE_HOME`` for Mesa's
  shader cache, ``STUDYAPP_CACHE_DIR`` for the built-in avatar's), with only an untimed ``validate`` before
  it. The first figure's caches are those an earlier start filled (the next participant on a lab PC, a
  resumed session); this one is the first participant's first start. ``validate`` fills the GL driver's
  shader cache there (:mod:`studyapp.render.warmup`), as it does on the lab PC it runs on;
* the same once more with the driver's shader cache empty (``validate`` ran with another ``XDG_CACHE_HOME``):
  a PC where the design was validated elsewhere, or whose driver cache was cleared, so the first frame
  compiles every program (``first_trial_frame_empty_driver_cache_s``; no target, shown so the figure above
  does not hide the compile it avoids).

The package's bytecode is compiled first (``compileall``), as ``pip install`` does for a participant's copy:
with ``PYTHONDONTWRITEBYTECODE`` set and no ``__pycache__`` in a checkout, every cold start would otherwise
compile each module again (0.4-1 s here), a cost no installed copy pays.

Medians with min-max; the load average is printed and recorded (``startup_help_ratio_vs_numpy``,
``first_trial_frame_s``, ``first_trial_frame_fresh_machine_s``) with :func:`figures.record` for ``run_all.py --json``.
Usage: ``python benchmarks/bench_startup.py [runs]`` (default 5).
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

FIRST_FRAME = r"""
# Run as a file, as the `studyapp` console script is: a spawned child (the audio output) imports this file
# as the parent's main module, as it imports the console script, and so pays for `studyapp.cli` too.
import json, time
T0 = time.perf_counter()
import studyapp.cli  # the console script's import


def _main():
    t = T0
    phases = {}
    from studyapp.audio.playback import PendingClock
    from studyapp.render.context import create_offscreen_context
    from studyapp.render.renderer import Renderer
    from studyapp.render.scene import build_trial_scene
    from studyapp.resources import demo_design
    from studyapp.study.design import load_design
    from studyapp.study.schedule import participant_schedule
    from studyapp.study.stimuli import load_trial_media
    from studyapp.ui.layer import ImGuiLayer
    from studyapp.ui.scene_cache import SceneCache
    phases["imports"] = time.perf_counter() - t
    t = time.perf_counter()
    audio = PendingClock(None)  # as `studyapp run` starts it, before the design: it opens while the rest loads
    phases["audio output started"] = time.perf_counter() - t
    t = time.perf_counter()
    design = load_design(demo_design(), reuse_check=True)  # as `studyapp demo` and `run` start a session
    plan = [p for p in participant_schedule(design, "P01", row=0) if not p.is_practice][0]
    phases["design + schedule"] = time.perf_counter() - t
    # in the order of the participant window (studyapp.ui.app.run_window, WindowRunner, StudyApp): the window
    # and its GL context, the UI library, the UI, a "Loading..." frame, then the trial (TrialView.load after
    # that frame's flip) and its first frame. No frame waits for the audio output (StudyApp takes it after
    # the first flip that finds it open); its process runs meanwhile, on the same cores.
    t = time.perf_counter()
    ctx = create_offscreen_context()
    phases["GL context"] = time.perf_counter() - t
    t = time.perf_counter()
    from imgui_bundle import imgui
    phases["UI library import"] = time.perf_counter() - t
    t = time.perf_counter()
    layer = ImGuiLayer(ctx)
    W, H, FOOT = 1280, 720, 84
    fbo = ctx.framebuffer([ctx.renderbuffer((W, H), 4)], ctx.depth_renderbuffer((W, H)))
    fbo.use()
    fbo.clear(0.11, 0.12, 0.14, 1.0, depth=1.0)
    ctx.viewport = (0, 0, W, H)
    layer.new_frame((W, H), 1 / 60)
    imgui.begin("loading")
    imgui.text("Loading...")
    imgui.end()
    layer.render((W, H))
    fbo.read(components=3)  # the flip: the frame is on screen before the trial loads
    phases["UI layer + loading frame"] = time.perf_counter() - t
    t = time.perf_counter()
    media = load_trial_media(design, plan)
    phases["trial media (motion, audio, avatars)"] = time.perf_counter() - t
    t = time.perf_counter()
    renderer = Renderer(ctx)
    scene = build_trial_scene(renderer, media)
    phases["renderer + scene (shaders, uploads)"] = time.perf_counter() - t
    t = time.perf_counter()
    # the participant's trial frame (StudyApp.frame): the 3D view above the answer footer, the UI drawn on top
    SceneCache(ctx).draw(renderer, scene, 0.0, fbo, (0, FOOT, W, H - FOOT), (W, H), (0.11, 0.12, 0.14))
    fbo.use()
    ctx.viewport = (0, 0, W, H)
    layer.new_frame((W, H), 1 / 60)
    imgui.set_next_window_pos((0, H - FOOT))
    imgui.set_next_window_size((W, FOOT))
    imgui.begin("footer")
    imgui.text("Play the clip, then rank the three figures.")
    imgui.button("Play")
    imgui.end()
    layer.render((W, H))
    import numpy as np
    img = np.frombuffer(fbo.read(components=3), np.uint8).reshape(H, W, 3)
    phases["first frame (draw + UI + read-back)"] = time.perf_counter() - t
    done = time.time()
    open_by_then = audio.done()
    clock, message = audio.result()
    print(json.dumps({"done": done, "phases": phases, "shape": list(img.shape), "lit": float(img.std()),
                      "audio": getattr(clock, "device_name", "none"), "audio_open_by_then": open_by_then}))
    clock.close()
    audio.close()


if __name__ == "__main__":
    _main()
"""


def _cold(cmd: list[str]) -> float:
    t = time.perf_counter()
    subprocess.run(cmd, check=True, capture_output=True, cwd=_code_root())
    return time.perf_counter() - t


def _code_root() -> str:
    """The folder holding the studyapp being measured (the one ``PYTHONPATH`` or the install gives), where
    the ``python -m studyapp.cli`` commands run: ``-m`` puts the working folder first on the path, so run
    from another checkout they would measure that checkout's code."""
    import studyapp
    return str(Path(studyapp.__file__).resolve().parents[1])


def _children_cpu() -> float:
    import resource
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _first_frame(script: Path, env: dict[str, str] | None = None) -> dict:
    cpu0 = _children_cpu()
    start = time.time()
    out = subprocess.run([sys.executable, str(script)], check=True, capture_output=True, text=True,
                         env=None if env is None else {**os.environ, **env}).stdout
    res = json.loads(out.strip().splitlines()[-1])
    res["total"] = res["done"] - start
    # CPU seconds of the whole process (all its threads, llvmpipe's included): on a shared machine whose load
    # exceeds its cores, wall time mostly measures the other jobs
    res["cpu"] = _children_cpu() - cpu0
    return res


def _fmt(xs: list[float]) -> str:
    return f"{statistics.median(xs):7.3f} s (min {min(xs):.3f}, max {max(xs):.3f})"


def _byte_compile() -> None:
    """Compile the package's bytecode as an installed copy has it (see the module text)."""
    import compileall

    import studyapp
    compileall.compile_dir(str(Path(studyapp.__file__).parent), quiet=2)


def main(argv: list[str]) -> int:
    from figures import record
    from studyapp.resources import demo_design
    runs = int(argv[0]) if argv else 5
    _byte_compile()
    py = sys.executable
    cmds = {"python -c 'import numpy'": [py, "-c", "import numpy"],
            "studyapp --help": [py, "-m", "studyapp.cli", "--help"],
            "studyapp validate demo.toml": [py, "-m", "studyapp.cli", "validate", str(demo_design())]}
    audio_env, audio_pid = _null_audio()
    load_before = os.getloadavg()
    times: dict[str, list[float]] = {k: [] for k in cmds}
    frames, fresh_frames, nodriver_frames = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "first_frame.py"
        script.write_text(FIRST_FRAME)
        saved = {k: os.environ.get(k) for k in audio_env}
        os.environ.update(audio_env)
        try:
            for r in range(runs):
                order = list(cmds) if r % 2 == 0 else list(reversed(cmds))
                for k in order:
                    times[k].append(_cold(cmds[k]))
                frames.append(_first_frame(script))
                # the same on a machine where the app never ran: empty caches (Mesa's shader cache, the
                # built-in avatar's), after the experimenter's `validate` there (untimed, as in the lab)
                fresh = {"XDG_CACHE_HOME": str(Path(tmp) / f"cache{r}"),
                         "STUDYAPP_CACHE_DIR": str(Path(tmp) / f"cache{r}" / "studyapp")}
                subprocess.run(cmds["studyapp validate demo.toml"], check=True, capture_output=True, cwd=_code_root(),
                               env={**os.environ, **fresh})
                fresh_frames.append(_first_frame(script, fresh))
                # validated here, but the driver's shader cache empty (validated with another XDG_CACHE_HOME)
                nodriver = {"XDG_CACHE_HOME": str(Path(tmp) / f"driver{r}"),
                            "STUDYAPP_CACHE_DIR": str(Path(tmp) / f"app{r}")}
                subprocess.run(cmds["studyapp validate demo.toml"], check=True, capture_output=True, cwd=_code_root(),
                               env={**os.environ, **nodriver, "XDG_CACHE_HOME": str(Path(tmp) / f"elsewhere{r}")})
                nodriver_frames.append(_first_frame(script, nodriver))
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
            if audio_pid is not None:
                os.kill(audio_pid, signal.SIGTERM)
    load_after = os.getloadavg()
    print(f"{runs} cold runs each, interleaved; load average {load_before[0]:.2f} before, {load_after[0]:.2f} "
          f"after ({os.cpu_count()} cores)")
    for k, xs in times.items():
        print(f"  {k:40s} {_fmt(xs)}")
    bare, help_ = statistics.median(times[cmds_key(cmds, 0)]), statistics.median(times[cmds_key(cmds, 1)])
    print(f"  --help / import numpy: {help_ / bare:.2f}x (target <= 2x)")
    audio = frames[0]["audio"]
    open_by_then = sum(f["audio_open_by_then"] for f in frames + fresh_frames + nodriver_frames)
    print(f"  first trial frame of the demo, offscreen 1280x720, UI included, from process start (audio output: "
          f"{audio}{'' if audio != 'none' else ': NOT MEASURED, no output device and no pulseaudio for a null sink'}):")
    for phase in frames[0]["phases"]:
        print(f"    {phase:38s} {_fmt([f['phases'][phase] for f in frames])}")
    totals = [f["total"] for f in frames]
    print(f"    {'total (incl. interpreter start)':38s} {_fmt(totals)}  (target <= 1.5 s)")
    cpus = [f["cpu"] for f in frames]
    print(f"    {'CPU time of that process':38s} {_fmt(cpus)}")
    print("  the same on a machine where the app never ran (empty caches; the experimenter's `validate` before it):")
    for phase in fresh_frames[0]["phases"]:
        print(f"    {phase:38s} {_fmt([f['phases'][phase] for f in fresh_frames])}")
    fresh_totals, fresh_cpus = [f["total"] for f in fresh_frames], [f["cpu"] for f in fresh_frames]
    print(f"    {'total (incl. interpreter start)':38s} {_fmt(fresh_totals)}  (target <= 1.5 s)")
    print(f"    {'CPU time of that process':38s} {_fmt(fresh_cpus)}")
    print("  the same with the GL driver's shader cache empty (validated with another cache folder):")
    nodriver_totals, nodriver_cpus = [f["total"] for f in nodriver_frames], [f["cpu"] for f in nodriver_frames]
    print(f"    {'first frame (draw + UI + read-back)':38s} "
          f"{_fmt([f['phases']['first frame (draw + UI + read-back)'] for f in nodriver_frames])}")
    print(f"    {'total (incl. interpreter start)':38s} {_fmt(nodriver_totals)}")
    print(f"    {'CPU time of that process':38s} {_fmt(nodriver_cpus)}")
    print(f"  the audio output was open by the first trial frame in {open_by_then} of {3 * runs} starts (no frame "
          "waits for it; CPU time above includes its process)")
    common = {"runs": runs, "loadavg": [load_before[0], load_after[0]], "cores": os.cpu_count()}
    record("startup_help_ratio_vs_numpy", value=help_ / bare, baseline=1.0, unit="x bare `import numpy` time",
           help_s=help_, numpy_s=bare, validate_s=statistics.median(times[cmds_key(cmds, 2)]), target=2.0,
           note="cold `studyapp --help` vs cold `python -c 'import numpy'`, medians, interleaved", **common)
    first_frame_notes = {
        "first_trial_frame_s": (frames, "process start to the demo's first trial frame (the 3D view and the UI "
                                "over it) rendered offscreen and read back, with the audio output opened as "
                                "`studyapp run` opens it; baseline = the 1.5 s target"),
        "first_trial_frame_fresh_machine_s": (fresh_frames, "as first_trial_frame_s, on a machine where the app "
                                              "never ran: empty caches (Mesa's shader cache, the built-in avatar's); "
                                              "only the experimenter's `validate` ran before it (which fills the GL "
                                              "driver's shader cache on the machine it runs on)"),
        "first_trial_frame_empty_driver_cache_s": (nodriver_frames, "as first_trial_frame_fresh_machine_s, but "
                                                   "`validate` ran with another driver cache folder: the first frame "
                                                   "compiles every GL program (a PC where the design was validated "
                                                   "elsewhere)"),
    }
    for key, (runs_of, note) in first_frame_notes.items():
        tot, cpu = [f["total"] for f in runs_of], [f["cpu"] for f in runs_of]
        record(key, value=statistics.median(tot), baseline=1.5, unit="s", spread=[min(tot), max(tot)],
               cpu_s=statistics.median(cpu), cpu_spread=[min(cpu), max(cpu)], audio_output=audio,
               phases={p: statistics.median(f["phases"][p] for f in runs_of) for p in runs_of[0]["phases"]},
               note=note, **common)
    return 0


def _null_audio() -> tuple[dict[str, str], int | None]:
    """A null PulseAudio sink when there is no sound server (CI, this headless machine), so the first frame's
    figure includes opening the audio output as a participant's machine, which has a sound card, does.
    Returns the environment to set and the pid to end (None: one was running already)."""
    if os.environ.get("PULSE_SERVER") or not shutil.which("pulseaudio"):
        return {}, None
    script = HERE.parent / ".ci" / "start-null-audio.sh"
    out = subprocess.run(["bash", str(script)], capture_output=True, text=True, timeout=30).stdout
    env = {k: v.strip("'\"") for k, v in (tok.split("=", 1) for tok in out.replace("export ", "").split() if "=" in tok)}
    pid = env.pop("AUDIO_NULL_PID", None)
    return (env, int(pid)) if pid else ({}, None)


def cmds_key(cmds: dict, i: int) -> str:
    return list(cmds)[i]


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
