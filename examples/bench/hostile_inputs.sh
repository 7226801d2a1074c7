#!/usr/bin/env bash
# Runs VMAP_BINARY on crafted inputs that once hung it or made it allocate what the input
# claims instead of what it holds, and prints each run's exit code, wall time and peak
# resident memory (GNU time's "Maximum resident set size"):
#
#   examples/bench/hostile_inputs.sh VMAP_BINARY OUTDIR [CHUNKS=300]
#
#   fifo       `build` and `calibrate` of a FIFO named f.bag, f.mcap, f.db3 and f, and
#              `bag info` / `build` of a rosbag2 folder whose metadata.yaml lists a FIFO;
#              each under `timeout 20` (exit 124: it waited on the FIFO)
#   db3        `build` of a rosbag2 .db3 holding one message of 900 MiB (zeroblob: a
#              sparse-looking file of 900 MiB on disk)
#   chunks     `bag info` of bags of CHUNKS chunks, each stating 512 MiB uncompressed for
#              5 kB of data (ROS 1 lz4 and bz2, MCAP lz4 and zstd; no index or summary, so
#              every chunk is read)
#   yml.gz     `vocabulary convert` of a 1 MB gzipped DBoW2 YAML that inflates to 1 GiB
#              less 1 MiB of filler
#   floor      `--version`: the program's own start-up, for comparison
# The crafted files are written once into OUTDIR/in (about 1 GB, most of it the .db3).
# Needs python3, lz4 and zstd (Debian: lz4, zstd) and GNU time (/usr/bin/time).
set -euo pipefail

if [[ $# -lt 2 ]]; then
  echo "usage: $0 VMAP_BINARY OUTDIR [CHUNKS=300]" >&2
  exit 2
fi
VMAP=$(realpath "$1")
OUT_DIR=$(realpath -m "$2")
CHUNKS=${3:-300}
IN=$OUT_DIR/in
mkdir -p "$IN"

python3 - "$IN" "$CHUNKS" <<'EOF'
import bz2, gzip, os, sqlite3, struct, subprocess, sys

out, chunks = sys.argv[1], int(sys.argv[2])
claim = 512 << 20
payload = bytes(range(256)) * 10 + b"\0" * 2440  # 5000 bytes


def pipe(tool, data):
    return subprocess.run([tool, "-c", "-q"], input=data, capture_output=True, check=True).stdout


def field(name, value):
    f = name.encode() + b"=" + value
    return struct.pack("<I", len(f)) + f


def record(fields, data):
    h = b"".join(fields)
    return struct.pack("<I", len(h)) + h + struct.pack("<I", len(data)) + data


def ros1(path, codec):  # bag header with index_pos 0 (no index), then the chunks
    fields = [field("op", b"\x03"), field("index_pos", struct.pack("<Q", 0)),
              field("conn_count", struct.pack("<I", 0)), field("chunk_count", struct.pack("<I", 0))]
    head = record(fields, b"")
    head = record(fields, b" " * (4096 - len(head)))
    data = pipe("lz4", payload) if codec == "lz4" else bz2.compress(payload)
    chunk = record([field("op", b"\x05"), field("compression", codec.encode()),
                    field("size", struct.pack("<I", claim))], data)
    with open(path, "wb") as f:
        f.write(b"#ROSBAG V2.0\n" + head + chunk * chunks)


def mcap_record(op, body):
    return bytes([op]) + struct.pack("<Q", len(body)) + body


def mcap_string(s):
    return struct.pack("<I", len(s)) + s


def mcap(path, codec):  # header, chunks, data end, a footer without a summary
    data = pipe(codec, payload)
    chunk = mcap_record(0x06, struct.pack("<QQQI", 0, 0, claim, 0) + mcap_string(codec.encode()) +
                        struct.pack("<Q", len(data)) + data)
    with open(path, "wb") as f:
        f.write(b"\x89MCAP0\r\n" + mcap_record(0x01, mcap_string(b"ros2") + mcap_string(b"craft")) +
                chunk * chunks + mcap_record(0x0F, struct.pack("<I", 0)) +
                mcap_record(0x02, struct.pack("<QQI", 0, 0, 0)) + b"\x89MCAP0\r\n")


for codec in ("lz4", "bz2"):
    ros1(f"{out}/claims_{codec}.bag", codec)
for codec in ("lz4", "zstd"):
    mcap(f"{out}/claims_{codec}.mcap", codec)

db3 = f"{out}/big_message.db3"
if not os.path.exists(db3):
    db = sqlite3.connect(db3)
    db.executescript("""
      CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL,
                          serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);
      CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL,
                            data BLOB NOT NULL);
      INSERT INTO topics VALUES (1, '/cam/image_raw', 'sensor_msgs/msg/Image', 'cdr', '');""")
    db.execute("INSERT INTO messages(topic_id, timestamp, data) VALUES (1, 1, zeroblob(?))", (900 << 20,))
    db.commit()
    db.close()

yml = f"{out}/filler.yml.gz"
if not os.path.exists(yml):
    with gzip.open(yml, "wb", compresslevel=9) as f:
        f.write(b'%YAML:1.0\n---\nvocabulary:\n   k: 10\n   L: 3\n   x: "')
        block = b" " * (1 << 20)
        for _ in range(1023):
            f.write(block)
        f.write(b'"\n')
EOF

rm -rf "$IN/fifo" && mkdir -p "$IN/fifo/listed"
for n in f.bag f.mcap f.db3 f; do mkfifo "$IN/fifo/$n"; done
python3 -c "import sqlite3,sys; sqlite3.connect(sys.argv[1]).executescript(
  'CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT, type TEXT, serialization_format TEXT, offered_qos_profiles TEXT);'
  'CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER, timestamp INTEGER, data BLOB);')" "$IN/fifo/listed/a.db3"
mkfifo "$IN/fifo/listed/b.db3"
printf 'rosbag2_bagfile_information:\n  relative_file_paths:\n    - a.db3\n    - b.db3\n' > "$IN/fifo/listed/metadata.yaml"

run() {  # LABEL ARGS...: one run in IN, bounded by 20 s for the FIFOs
  local label=$1 log=$OUT_DIR/time.log
  shift
  (cd "$IN" && /usr/bin/time -v timeout -s KILL 600 "$VMAP" "$@" >/dev/null 2>"$log") || true
  local rss wall code
  rss=$(awk '/Maximum resident/ {print $NF}' "$log")
  wall=$(awk '/Elapsed \(wall/ {print $NF}' "$log")
  code=$(awk '/Exit status/ {print $NF}' "$log")
  printf '%-34s exit %3s  %9s  %8.1f MiB  %s\n' "$label" "$code" "$wall" "$(echo "$rss / 1024" | bc -l)" \
    "$(grep -m1 '^vmap' "$log" | cut -c1-110)"
}
fifo() {  # LABEL ARGS...: as run, killed after 20 s
  local label=$1
  shift
  local t0 t1 code
  t0=$(date +%s.%N)
  (cd "$IN" && timeout 20 "$VMAP" "$@" >/dev/null 2>"$OUT_DIR/fifo.log") && code=0 || code=$?
  t1=$(date +%s.%N)
  printf '%-34s exit %3s  %7.1f s  %s\n' "$label" "$code" "$(echo "$t1 - $t0" | bc -l)" \
    "$(grep -m1 '^vmap' "$OUT_DIR/fifo.log" | cut -c1-110)"
}

for n in f.bag f.mcap f.db3 f; do fifo "fifo: build $n" build "fifo/$n"; done
fifo "fifo: calibrate f f" calibrate fifo/f fifo/f
fifo "fifo: bag info (metadata lists one)" bag info fifo/listed
fifo "fifo: build (metadata lists one)" build fifo/listed
run "floor: --version" --version
run "db3: build (900 MiB message)" build big_message.db3
for f in claims_lz4.bag claims_bz2.bag claims_lz4.mcap claims_zstd.mcap; do
  run "chunks: bag info $f" bag info "$f"
done
run "yml.gz: vocabulary convert" vocabulary convert filler.yml.gz "$OUT_DIR/filler.vmapvoc" --force
