#!/usr/bin/env bash
# A throwaway PostgreSQL cluster for tests and benchmarks, from Debian's packages.
#   scripts/pg_cluster.sh start DIR PORT   # initdb (first time) + start; prints the URL
#                                          # (PORT 0: a free one, tried until one binds)
#   scripts/pg_cluster.sh stop DIR         # fast shutdown
#   scripts/pg_cluster.sh restart DIR      # immediate stop (as a crash) + start
# Listens on 127.0.0.1:PORT and a unix socket in DIR; user `vf`, trust auth, database `postgres`.
# As root the server runs as the `postgres` user (PostgreSQL refuses to run as root).
# PG_FAST=1 turns fsync off (tests); benchmarks leave it on.
set -euo pipefail
cmd=${1:?start|stop|restart}; dir=${2:?cluster directory}; port=${3:-}
bindir=""
if command -v pg_config >/dev/null && [ -x "$(pg_config --bindir)/initdb" ]; then bindir=$(pg_config --bindir); fi
if [ -z "$bindir" ]; then bindir=$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -1 || true); fi
if [ -z "$bindir" ] || [ ! -x "$bindir/initdb" ]; then
  echo "PostgreSQL server binaries not found (Debian: apt-get install postgresql)" >&2; exit 3
fi
as_pg=()
if [ "$(id -u)" = 0 ]; then as_pg=(runuser -u postgres --); fi
data="$dir/data"
random_port() { echo $((20000 + RANDOM % 40000)); }
case "$cmd" in
  start)
    [ -n "$port" ] || { echo "start needs a PORT" >&2; exit 2; }
    mkdir -p "$dir"
    if [ "$(id -u)" = 0 ]; then chown postgres "$dir"; fi
    if [ ! -f "$data/PG_VERSION" ]; then
      "${as_pg[@]}" "$bindir/initdb" -D "$data" -A trust -U vf --no-sync -E UTF8 >"$dir/initdb.log" 2>&1 \
        || { cat "$dir/initdb.log" >&2; exit 1; }
      {
        if [ "$port" = 0 ]; then echo "port = $(random_port)"; else echo "port = $port"; fi
        echo "listen_addresses = '127.0.0.1'"
        echo "unix_socket_directories = '$dir'"
        echo "max_connections = 400"
        echo "shared_buffers = 128MB"
        if [ "${PG_FAST:-0}" = 1 ]; then echo "fsync = off"; echo "synchronous_commit = off"; echo "full_page_writes = off"; fi
      } >>"$data/postgresql.conf"
    fi
    # PORT 0: the cluster's last port if it still binds, else random ones until one does (a
    # port probed free beforehand could be taken before the server binds it).
    tries=1; [ "$port" = 0 ] && tries=20
    for ((i = 1; ; i++)); do
      if "${as_pg[@]}" "$bindir/pg_ctl" -D "$data" -l "$dir/server.log" -w -t 60 start >/dev/null; then
        break
      fi
      if [ "$i" -ge "$tries" ]; then tail -5 "$dir/server.log" >&2; exit 1; fi
      echo "port = $(random_port)" >>"$data/postgresql.conf"
    done
    echo "postgres://vf@127.0.0.1:$(sed -n 's/^port = //p' "$data/postgresql.conf" | tail -1)/postgres"
    ;;
  stop)
    "${as_pg[@]}" "$bindir/pg_ctl" -D "$data" -m fast -w stop >/dev/null 2>&1 || true
    ;;
  restart)
    "${as_pg[@]}" "$bindir/pg_ctl" -D "$data" -m immediate -w stop >/dev/null 2>&1 || true
    "${as_pg[@]}" "$bindir/pg_ctl" -D "$data" -l "$dir/server.log" -w -t 60 start >/dev/null
    ;;
  *) echo "unknown command $cmd" >&2; exit 2 ;;
esac
