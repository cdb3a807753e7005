#!/usr/bin/env bash
# Start a PulseAudio daemon with one null sink so PortAudio (sounddevice) gets a real-time-paced output
# device on machines without a sound card (CI, headless servers). Prints `export ...` lines to eval:
#   eval "$(.ci/start-null-audio.sh)"  ...  kill "$AUDIO_NULL_PID"
# The first ~0.5-1.5 s after start deliver few callbacks; timing code warms up before measuring.
set -eu
base=$(mktemp -d /tmp/null-audio.XXXXXX)
export HOME="$base/home" XDG_RUNTIME_DIR="$base/run"
mkdir -p "$HOME" "$XDG_RUNTIME_DIR"; chmod 700 "$XDG_RUNTIME_DIR"
pulseaudio --daemonize=no -n --exit-idle-time=-1 --disallow-exit \
  --load="module-null-sink sink_name=nullsink rate=48000 sink_properties=device.description=NullSink" \
  --load="module-native-protocol-unix" --load="module-always-sink" \
  --log-target=file:"$base/pulse.log" --log-level=notice >/dev/null 2>&1 &
pid=$!
for _ in $(seq 50); do [ -S "$XDG_RUNTIME_DIR/pulse/native" ] && break; sleep 0.1; done
[ -S "$XDG_RUNTIME_DIR/pulse/native" ] || { echo "echo 'null audio did not start; see $base/pulse.log' >&2"; exit 1; }
echo "export XDG_RUNTIME_DIR='$XDG_RUNTIME_DIR' PULSE_SERVER='unix:$XDG_RUNTIME_DIR/pulse/native' AUDIO_NULL_PID=$pid"
