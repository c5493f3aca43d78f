"""Cost of recording in `twin sim`: the humanoid with and without `--record`, interleaved.

    python3 benches/sim_record.py target/release/twin DURATION_SECS REPEATS

Each repeat runs every variant once (same load for all); prints a Markdown table with the
wall time of the loop + closing the file, the CPU time of the simulation thread (what
`twin sim` prints as "simulation thread CPU", from /proc/thread-self/schedstat), and the
process CPU time (writer thread included). Output file: /tmp/twin_sim_record_bench.mcap.
"""
import re, subprocess, sys, resource, statistics, os
twin = sys.argv[1]; dur = sys.argv[2]; reps = int(sys.argv[3])
variants = {
    "none": [],
    "zstd thread": ["--record", "/tmp/twin_sim_record_bench.mcap"],
    "lz4 thread": ["--record", "/tmp/twin_sim_record_bench.mcap", "--compression", "lz4"],
    "zstd inline": ["--record", "/tmp/twin_sim_record_bench.mcap", "--inline-writer"],
    "lz4 inline": ["--record", "/tmp/twin_sim_record_bench.mcap", "--compression", "lz4", "--inline-writer"],
    "none compr. thread": ["--record", "/tmp/twin_sim_record_bench.mcap", "--compression", "none"],
    "JointState only, zstd thread": ["--record", "/tmp/twin_sim_record_bench.mcap", "--topics", "/joint_states"],
    "JointState only, zstd inline": ["--record", "/tmp/twin_sim_record_bench.mcap", "--topics", "/joint_states", "--inline-writer"],
}
extra = sys.argv[4:]  # e.g. --rate 500
res = {k: [] for k in variants}
for r in range(reps):
    for k, a in variants.items():
        if os.path.exists("/tmp/twin_sim_record_bench.mcap"): os.remove("/tmp/twin_sim_record_bench.mcap")
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        out = subprocess.run([twin, "sim", "--duration", dur] + a + extra, capture_output=True, text=True, check=True).stdout
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        loop = float(re.search(r"in ([0-9.]+) s wall", out).group(1))
        tcpu = float(re.search(r"thread CPU: ([0-9.]+) s", out).group(1))
        m = re.search(r"recording: ([0-9.]+) s inside.*?([0-9.]+) s to close", out)
        inside, close = (float(m.group(1)), float(m.group(2))) if m else (0.0, 0.0)
        size = re.search(r"bench.mcap: (\d+) messages, \d+ chunks, (\d+) bytes", out)
        res[k].append((loop, inside, close, cpu, tcpu, int(size.group(2)) if size else 0, int(size.group(1)) if size else 0))
        res[k][-1] = res[k][-1][:4] + res[k][-1][5:] + (tcpu,)
base_best = min(x[0] for x in res["none"]); base_med = statistics.median(x[0] for x in res["none"])
steps = round(float(dur) / 0.002)
print(f"load: {os.getloadavg()}  steps per run: {steps}")
tb_best = min(x[6] for x in res["none"]); tb_med = statistics.median(x[6] for x in res["none"])
print("| variant | wall, loop + close: best / median (s) | wall cost vs no recording: best / median | sim-thread CPU per step: best / median (µs) | sim-thread CPU cost: best / median | process CPU (s, median) | file (MB) | messages |")
print("| --- | --- | --- | --- | --- | --- | --- | --- |")
for k, v in res.items():
    tot = [x[0] + x[2] for x in v]
    best, med = min(tot), statistics.median(tot)
    ins = statistics.median(x[1] for x in v) * 1e6 / steps
    cpu = statistics.median(x[3] for x in v)
    tc = [x[6] for x in v]
    print(f"| {k} | {best:.3f} / {med:.3f} | {100*(best/base_best-1):+.1f} % / {100*(med/base_med-1):+.1f} % | {min(tc)*1e6/steps:.2f} / {statistics.median(tc)*1e6/steps:.2f} | {100*(min(tc)/tb_best-1):+.1f} % / {100*(statistics.median(tc)/tb_med-1):+.1f} % | {cpu:.2f} | {v[0][4]/1e6:.1f} | {v[0][5]} |")
