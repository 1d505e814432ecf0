#!/usr/bin/env bash
# Runs the store's tests (the collector's store_tests, the store crate's grasp, results
# and calibration round trips), the collect, dataset, fault and resume tests (and db copy and several rigs
# at once) against a throwaway PostgreSQL server: initdb into a temporary folder as an
# unprivileged user (PostgreSQL refuses root), a free port on loopback, stopped and
# removed on every exit. Needs Debian's `postgresql` package (initdb, pg_ctl).
#
#   bash scripts/test-postgres.sh                 # the PostgreSQL tier, as CI runs it
#   bash scripts/test-postgres.sh --test end_to_end -- faults::   # other `cargo test` arguments instead
#   SOFTTOUCH_PG_LOCALE=C bash scripts/test-postgres.sh ...   # a byte-order cluster
#
# The cluster's collation is ICU's en-US unless SOFTTOUCH_PG_LOCALE says otherwise
# (`C`, or another ICU locale): most servers sort text by a language's rules, not by
# bytes as SQLite does, and the store must give the same order and hashes on both.
# The role `softtouch_pw` logs in over TCP with a password only (scram-sha-256), so
# that the secrets test (tests/postgres.rs) sees a server that checks one; every other
# user is trusted, as a throwaway server's may be.
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
LOCALE=${SOFTTOUCH_PG_LOCALE:-en-US}
if [ "$LOCALE" = C ]; then
    locale_args="--locale=C"
else
    locale_args="--locale=C.UTF-8 --locale-provider=icu --icu-locale=$LOCALE"
fi
as_db_user "'$BIN/initdb' -D '$DIR/data' -U postgres --auth=trust -E UTF8 $locale_args >/dev/null"
# Before the trust lines: pg_hba.conf is read top down, the first match wins.
as_db_user "sed -i '1i host all softtouch_pw 127.0.0.1/32 scram-sha-256' '$DIR/data/pg_hba.conf'"
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
export SOFTTOUCH_TEST_POSTGRES_PASSWORD_ROLE=softtouch_pw
echo "PostgreSQL $("$BIN/postgres" --version | awk '{print $3}') on port $PORT, collation $LOCALE"
# --workspace, as the README's test command: the same features, so nothing is rebuilt.
if [ $# -eq 0 ]; then
    cargo test --release --workspace --lib -- store_tests grasp:: results:: grasp_calibration:: copy::
    cargo test --release --workspace --test end_to_end -- collect:: dataset:: faults:: \
        resume:: postgres::
else
    cargo test --release "$@"
fi
