# Shared setup for the real-LinuxCNC tests (sourced by run.sh and the test scripts).
#
# - As root, rtapi_app refuses to start unless RTAPI_UID names an unprivileged user.
#   RTAPI_FIFO_PATH is the path of rtapi_app's control *socket* (not a directory); the directory
#   holding it must be writable by that user (/tmp is; a root-owned mktemp -d is not). If the path
#   exists as a directory, `rtapi_app exit` retries connect() forever: hence the timeouts below.
# - A killed session leaves rtapi_app and the HAL shared memory behind: `halrun -U` before each
#   session and on exit.
# - Two halrun sessions on one machine collide: run.sh holds a lock for the whole suite.
# - A panic in a realtime function aborts rtapi_app while halrun still exits 0: every test checks
#   its results (sample counts) instead of trusting halrun's status.

set -euo pipefail

if [ "$(id -u)" = 0 ]; then
    export RTAPI_UID="${RTAPI_UID:-65534}"
    export RTAPI_FIFO_PATH="${RTAPI_FIFO_PATH:-/tmp/rtapi_fifo}"
    if [ -d "$RTAPI_FIFO_PATH" ]; then
        echo "RTAPI_FIFO_PATH=$RTAPI_FIFO_PATH is a directory; it must be a socket path" >&2
        exit 1
    fi
fi

hal_cleanup() {
    timeout 30 halrun -U >/dev/null 2>&1 || true
}

# hal_session FILE LOG: run one halrun session on FILE, output to LOG; fails if halrun does or
# if rtapi_app reported a crash.
hal_session() {
    local file=$1 log=$2
    hal_cleanup
    trap hal_cleanup EXIT
    local rc=0
    timeout "${HAL_TIMEOUT:-120}" halrun -f "$file" >"$log" 2>&1 || rc=$?
    hal_cleanup
    if [ $rc != 0 ]; then
        echo "halrun failed ($rc):"; cat "$log"; return 1
    fi
    if grep -E -i "panicked|aborted|segmentation|core dumped|rtapi_app.*(exited|killed)" "$log"; then
        echo "rtapi_app crashed:"; cat "$log"; return 1
    fi
}
