"""Audio output as the master clock: device selection, format conversion, and the clock on a real
(null PulseAudio) output that is paced in real time like a sound card."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from studyapp.audio.clock import SilentClock
from studyapp.audio.playback import (
    AudioDeviceError,
    OutputDevice,
    Pcm,
    _to_stream_format,
    open_clock,
    resolve_device,
    sound_check_tone,
)

SCRIPT = Path(__file__).resolve().parents[2] / ".ci" / "start-null-audio.sh"


def _rescan():
    import sounddevice as sd

    sd._terminate()
    sd._initialize()


@pytest.fixture(scope="module")
def null_sink():
    """Start a PulseAudio null sink (or use the one CI started) and export its environment."""
    if shutil.which("pulseaudio") is None:
        pytest.skip("pulseaudio is not installed: no null audio sink to play to")
    started = None
    saved = {k: os.environ.get(k) for k in ("PULSE_SERVER", "XDG_RUNTIME_DIR")}
    if not os.environ.get("PULSE_SERVER"):
        out = subprocess.run(["bash", str(SCRIPT)], capture_output=True, text=True, timeout=30)
        env = dict(tok.split("=", 1) for tok in out.stdout.replace("export ", "").split() if "=" in tok)
        env = {k: v.strip("'\"") for k, v in env.items()}
        if "PULSE_SERVER" not in env:
            pytest.skip(f"null audio sink did not start: {out.stdout} {out.stderr}")
        started = int(env.pop("AUDIO_NULL_PID"))
        os.environ.update(env)
    _rescan()
    yield os.environ["PULSE_SERVER"]
    if started is not None:
        os.kill(started, 15)
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        _rescan()


DEVICES = [
    OutputDevice(0, "HDA Intel PCH: ALC3246 Analog", "ALSA", 2, 48000.0, 0.01, 0.05, False),
    OutputDevice(3, "pulse", "ALSA", 32, 44100.0, 0.01, 0.03, False),
    OutputDevice(7, "default", "ALSA", 32, 44100.0, 0.01, 0.03, True),
]


def test_resolve_device_by_index_name_and_default():
    assert resolve_device(None, DEVICES).index == 7
    assert resolve_device(3, DEVICES).name == "pulse"
    assert resolve_device("3", DEVICES).name == "pulse"
    assert resolve_device("alc3246", DEVICES).index == 0
    assert resolve_device("DEFAULT", DEVICES).index == 7


def test_resolve_device_errors_list_the_outputs():
    with pytest.raises(AudioDeviceError, match="0: HDA Intel.*3: pulse.*7: default"):
        resolve_device("headphones", DEVICES)
    with pytest.raises(AudioDeviceError, match="no audio output device with index 9"):
        resolve_device(9, DEVICES)
    with pytest.raises(AudioDeviceError, match="no audio output device found"):
        resolve_device(None, [])


def test_stream_format_resamples_and_maps_channels():
    rate = 16000
    t = np.arange(rate) / rate
    mono = Pcm((0.5 * np.sin(2 * np.pi * 440 * t)).astype(np.float32)[:, None], rate)
    out = _to_stream_format(mono, 48000, 2)
    assert out.shape == (48000, 2) and out.dtype == np.float32
    assert np.array_equal(out[:, 0], out[:, 1])
    # the 440 Hz tone is still a 440 Hz tone at the new rate (independent check by FFT)
    spec = np.abs(np.fft.rfft(out[:, 0]))
    assert np.argmax(spec) == pytest.approx(440, abs=1)
    stereo = Pcm(np.stack([np.ones(10), -np.ones(10)], axis=1).astype(np.float32), 48000)
    assert np.allclose(_to_stream_format(stereo, 48000, 1)[:, 0], 0.0)  # down-mix averages


def test_sound_check_tone_has_no_clicks():
    tone = sound_check_tone(1000.0, 0.5, 48000)
    s = tone.samples[:, 0]
    assert abs(s[0]) < 1e-3 and abs(s[-1]) < 1e-3 and 0.29 < np.abs(s).max() <= 0.3


def test_silent_clock_real_time_follows_monotonic():
    clock = SilentClock()
    clock.play(None, duration_s=10.0)
    t0 = time.monotonic()
    time.sleep(0.05)
    elapsed = time.monotonic() - t0
    assert clock.position_s() == pytest.approx(elapsed, abs=0.02)
    clock.stop()
    assert not clock.playing and clock.position_s() == 0.0


def test_silent_clock_virtual_pause_replay():
    c = SilentClock(virtual=True)
    c.play(None, 1.0, duration_s=3.0)
    c.advance(0.5)
    assert c.position_s() == pytest.approx(1.5)
    c.pause()
    c.advance(2.0)
    assert c.paused and c.position_s() == pytest.approx(1.5)
    c.resume()
    c.advance(10.0)
    assert c.finished and c.position_s() == 3.0
    c.replay()
    assert c.position_s() == 0.0 and c.playing


def _wait_for(cond, timeout_s: float) -> bool:
    t_end = time.monotonic() + timeout_s
    while not cond():
        if time.monotonic() > t_end:
            return False
        time.sleep(0.01)
    return True


@pytest.mark.audio
def test_player_clock_follows_real_time_on_null_sink(null_sink):
    from studyapp.audio.playback import AudioPlayer, list_output_devices

    assert list_output_devices(), "the null sink should appear as an output"
    clip = Pcm(np.zeros((16000 * 12, 1), np.float32), 16000)
    with AudioPlayer() as player:
        assert player.wait_until_flowing(5.0)
        assert 0.0 < player.output_latency_s < 0.5
        player.play(clip)
        assert player.position_s() == 0.0
        # past the start latency (longer when the machine is busy): the clock moves once sound is audible
        assert _wait_for(lambda: player.position_s() > 0.0, 5.0), "the audio clock never started"
        # The audio clock advances with wall time (it is paced by the sink, not by us). An underrun stalls
        # the device, and the clock rightly with it: such a window measures the machine's load, not the
        # clock, so up to four windows are tried and one without an underrun must match.
        windows = []
        for _ in range(4):
            u0, p0, t0 = player.underflows, player.position_s(), time.monotonic()
            time.sleep(0.5)
            p1, t1 = player.position_s(), time.monotonic()
            windows.append((p1 - p0, t1 - t0, player.underflows - u0))
            if player.underflows == u0:
                break
        clean = [(dp, dt) for dp, dt, under in windows if under == 0]
        assert clean, f"every window had an underrun: {windows}"
        dp, dt = clean[-1]
        assert dp == pytest.approx(dt, abs=0.08), windows
        assert player.playing and not player.finished
        player.pause()
        frozen = player.position_s()
        time.sleep(0.2)
        assert player.paused and player.position_s() == frozen
        player.resume()
        assert _wait_for(lambda: player.position_s() > frozen, 3.0)
        player.stop()
        assert not player.playing


@pytest.mark.audio
def test_player_reaches_the_end(null_sink):
    from studyapp.audio.playback import AudioPlayer

    with AudioPlayer() as player:
        player.wait_until_flowing(5.0)
        player.play(sound_check_tone(duration_s=0.3, sample_rate=player.rate))
        t_end = time.monotonic() + 3.0
        while not player.finished and time.monotonic() < t_end:
            time.sleep(0.02)
        assert player.finished and player.position_s() == pytest.approx(player.duration_s)


def test_open_clock_without_device_is_silent_and_says_so():
    # the output process looks for the device itself: a fresh interpreter whose sound server does not exist
    code = ("from studyapp.audio.playback import list_output_devices, open_clock\n"
            "if __name__ == '__main__':\n"
            "    if list_output_devices():\n"
            "        print('HAS-CARDS')\n"
            "    else:\n"
            "        clock, message = open_clock(None)\n"
            "        print(type(clock).__name__, message)\n")
    env = {**os.environ, "PULSE_SERVER": "unix:/nonexistent/pulse/native"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60).stdout
    if "HAS-CARDS" in out:
        pytest.skip("this machine has sound cards: no way to show a machine without any")
    assert out.startswith("SilentClock ")
    assert "no audio output device" in out and "--audio-device" in out
    with pytest.raises(AudioDeviceError):
        open_clock("USB headset")  # a device asked for by name must exist


def _hold_gil(seconds: float) -> float:
    """Keep this interpreter's lock for about ``seconds`` in one C call (as moderngl does in a long GL
    call): ``list.sort`` of plain ints never releases it. Returns how long it really held it."""
    import random

    n = 200_000
    while True:
        data = [random.random() for _ in range(n)]
        t0 = time.monotonic()
        data.sort()
        took = time.monotonic() - t0
        if took >= seconds / 4 or n > 50_000_000:
            break
        n *= 4
    data = [random.random() for _ in range(int(n * seconds / max(took, 1e-3)))]
    t0 = time.monotonic()
    data.sort()
    return time.monotonic() - t0


@pytest.mark.audio
def test_player_clock_keeps_time_while_this_process_holds_the_gil(null_sink):
    """The stream's callback runs in the output process: a render thread holding the interpreter lock
    through a long GL call neither starves the device (no underflow) nor stalls the clock."""
    from studyapp.audio.playback import AudioPlayer

    clip = Pcm(np.zeros((16000 * 12, 1), np.float32), 16000)
    with AudioPlayer() as player:
        assert player.wait_until_flowing(5.0)
        player.play(clip)
        assert _wait_for(lambda: player.position_s() > 0.0, 5.0), "the audio clock never started"
        tries = []
        for _ in range(3):  # a window in which the machine itself stalled the sink does not count
            u0, p0, t0 = player.underflows, player.position_s(), time.monotonic()
            held = _hold_gil(0.6)
            p1, t1 = player.position_s(), time.monotonic()
            tries.append((round(held, 3), round(p1 - p0, 3), round(t1 - t0, 3), player.underflows - u0))
            if player.underflows == u0 and abs((p1 - p0) - (t1 - t0)) <= 0.08:
                break
        held, dp, dt, under = tries[-1]
        assert held >= 0.3, tries  # the lock really was held for a long stretch
        assert under == 0 and dp == pytest.approx(dt, abs=0.08), tries


def _watch_players(monkeypatch) -> list:
    """Every AudioPlayer made from now on, in order."""
    import studyapp.audio.playback as pb

    made = []
    real_init = pb.AudioPlayer.__init__

    def init(self, *args, **kwargs):
        real_init(self, *args, **kwargs)
        made.append(self)

    monkeypatch.setattr(pb.AudioPlayer, "__init__", init)
    return made


def _gone(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    return False


@pytest.mark.audio
def test_run_opens_the_audio_before_the_design_loads_and_the_window_uses_that_output(null_sink, tmp_path,
                                                                                      monkeypatch):
    import multiprocessing

    import studyapp.cli.session as cli_session
    import studyapp.ui.app as ui_app
    from studyapp.cli import main
    from studyapp.resources import demo_design

    made = _watch_players(monkeypatch)
    seen: dict = {}
    real_load = cli_session.load_design_for_run

    def load(*args, **kwargs):
        seen["players_when_the_design_loads"] = len(made)
        return real_load(*args, **kwargs)

    def window(design, db, pid, **kwargs):  # the window itself is tested under Xvfb; here: what it is handed
        clock, message = kwargs["audio"].result()
        seen.update(clock=clock, message=message, pid=clock._proc.pid, alive=clock._proc.is_alive())
        return 0

    monkeypatch.setattr(cli_session, "load_design_for_run", load)
    monkeypatch.setattr(ui_app, "run_window", window)
    monkeypatch.setenv("DISPLAY", ":99")  # only asked whether a window could open
    code = main(["run", str(demo_design()), "--participant", "P01", "--results", str(tmp_path / "r.sqlite")])
    assert code == 0
    assert seen["players_when_the_design_loads"] == 1     # started before the design was read
    assert len(made) == 1 and seen["clock"] is made[0]    # ... and the very output the window got
    assert seen["alive"] and seen["message"].startswith(f"audio output: {made[0].device.name} ")
    assert _gone(seen["pid"]) and multiprocessing.active_children() == []  # closed when the run ended


@pytest.mark.audio
def test_run_that_ends_before_its_window_leaves_no_audio_process(null_sink, tmp_path, monkeypatch, capsys):
    import multiprocessing

    from studyapp.cli import main

    made = _watch_players(monkeypatch)
    monkeypatch.setenv("DISPLAY", ":99")
    bad = tmp_path / "broken.toml"
    bad.write_text("title = [unclosed\n")
    code = main(["run", str(bad), "--participant", "P01", "--results", str(tmp_path / "r.sqlite")])
    assert code == 2 and "broken.toml" in capsys.readouterr().err
    assert len(made) == 1                                  # the output had been started early...
    player = made[0]
    assert player._proc is None                            # ... and was closed on the way out
    assert multiprocessing.active_children() == []


@pytest.mark.audio
def test_window_demo_opens_the_audio_while_the_design_loads(null_sink, tmp_path, monkeypatch):
    import multiprocessing

    import studyapp.study.design as design_mod
    import studyapp.ui.app as ui_app
    from studyapp.cli.demo import run_window_demo
    from studyapp.resources import demo_design

    made = _watch_players(monkeypatch)
    seen: dict = {}
    real_load = design_mod.load_design

    def load(*args, **kwargs):
        seen["players_when_the_design_loads"] = len(made)
        return real_load(*args, **kwargs)

    def window(design, db, pid, **kwargs):
        seen["clock"] = kwargs["audio"].result()[0]
        return 1  # closed before the end: no analysis to run

    monkeypatch.setattr(design_mod, "load_design", load)
    monkeypatch.setattr(ui_app, "run_window", window)
    assert run_window_demo(demo_design(), tmp_path / "out") == 1
    assert seen["players_when_the_design_loads"] == 1 and seen["clock"] is made[0]
    assert made[0]._proc is None and multiprocessing.active_children() == []
