#!/usr/bin/env bash
# Runs the store's tests (the collector's store_tests, the store crate's grasp, results
# and calibration round trips), the collect, dataset, fault and resume tests (and db copy and several rigs
# at once) against a throwaway PostgreSQL server: initdb into a temporary folder as an
# unprivileged user (PostgreSQL refuses root), a free port on loopback, stopped and
# removed on every exit. Needs Debian's `postgresql` package (initdb, pg_ctl).
#
#   bash scripts/test-postgres.sh                 # the PostgreSQL tier, as CI runs it
#   bash scripts/test-postgres.sh --test faults   # other `cargo test` arguments instead
#
# Against a server of your own instead: SOFTTOUCH_TEST_POSTGRES=postgres://USER@HOST/postgres
# cargo test --release ... (the user needs CREATEDB: every test makes a database of its own).
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -1)
if [ -z "$BIN" ] || [ ! -x "$BIN/initdb" ]; then
    echo "no PostgreSQL server binaries (apt-get install postgresql)" >&2
    exit 2
fi
DIR=$(mktemp -d /tmp/softtouch-pg.XXXXXX)
chmod 755 "$DIR"
# A free port: one nobody answers on (bash's /dev/tcp; no python needed).
free_port() {
    local p
    for _ in $(seq 50); do
        p=$(( 20000 + RANDOM % 40000 ))
        if ! (exec 3<>"/dev/tcp/127.0.0.1/$p") 2>/dev/null; then
            echo "$p"
            return 0
        fi
    done
    return 1
}
as_db_user() {
    if [ "$(id -u)" -eq 0 ]; then
        chown -R postgres "$DIR"
        su postgres -s /bin/bash -c "$*"
    else
        bash -c "$*"
    fi
}
stop() {
    as_db_user "'$BIN/pg_ctl' -D '$DIR/data' -m immediate stop >/dev/null 2>&1" || true
    rm -rf "$DIR"
}
trap stop EXIT
as_db_user "'$BIN/initdb' -D '$DIR/data' -U postgres --auth=trust -E UTF8 >/dev/null"
# Another process may take the port between the look and the start: try another.
for attempt in 1 2 3; do
    PORT=$(free_port)
    if as_db_user "'$BIN/pg_ctl' -D '$DIR/data' -l '$DIR/log' -w start \
        -o \"-p $PORT -k $DIR -c listen_addresses=127.0.0.1 -c max_connections=300\" >/dev/null"; then
        break
    fi
    [ "$attempt" -lt 3 ] || { cat "$DIR/log" >&2; exit 1; }
done
export SOFTTOUCH_TEST_POSTGRES="postgres://postgres@127.0.0.1:$PORT/postgres"
echo "PostgreSQL $("$BIN/postgres" --version | awk '{print $3}') on port $PORT"
# --workspace, as the README's test command: the same features, so nothing is rebuilt.
if [ $# -eq 0 ]; then
    cargo test --release --workspace --lib -- store_tests grasp:: results:: grasp_calibration::
    cargo test --release --workspace --test collect --test dataset --test faults \
        --test resume --test postgres
else
    cargo test --release "$@"
fi
