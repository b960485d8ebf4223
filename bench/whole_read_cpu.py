"""Issue 19: the whole volume through `ivol` (f[:]) against h5py on ivol's
own HDF5 export, timed by wall clock and by the process's CPU time (user +
system, all threads): on a shared machine whose load changes from second
to second, CPU time is what compares the two libraries' work. The reads
alternate, ivol then h5py, --repeat times; prints the medians and checks
that both returned the same values.

    PYTHONPATH=build/python /usr/bin/python3 bench/whole_read_cpu.py FILE.ivol FILE.h5 [--repeat 5]

FILE.h5 is what `ivol convert FILE.ivol FILE.h5` writes (bench/python_reads.py
makes it), dataset /exchange/data.
"""

import argparse
import resource
import statistics
import time

import h5py
import numpy as np

import ivol


def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def timed(fn):
    w, c = time.perf_counter(), cpu()
    out = fn()
    return time.perf_counter() - w, cpu() - c, out


def main():
    p = argparse.ArgumentParser()
    p.add_argument("ivol_file")
    p.add_argument("h5_file")
    p.add_argument("--repeat", type=int, default=5)
    a = p.parse_args()

    def read_ivol():
        return ivol.open(a.ivol_file)[:]

    def read_h5():
        with h5py.File(a.h5_file, "r") as f:
            return f["/exchange/data"][...]

    runs = {"ivol": [], "h5py": []}
    same = True
    for _ in range(a.repeat):
        wi, ci, x = timed(read_ivol)
        wh, ch, y = timed(read_h5)
        runs["ivol"].append((wi, ci))
        runs["h5py"].append((wh, ch))
        same = same and np.array_equal(x, y)
    f = ivol.open(a.ivol_file)
    print(f"{a.ivol_file}: {f.structure} {f.shape}; h5py {h5py.__version__}, ivol {ivol.library_version()}")
    print("library  wall s (median)  cpu s (median)")
    for name, r in runs.items():
        print(f"{name:8} {statistics.median(w for w, _ in r):14.3f} {statistics.median(c for _, c in r):15.3f}")
    ratio = statistics.median(c for _, c in runs["h5py"]) / statistics.median(c for _, c in runs["ivol"])
    print(f"h5py cpu / ivol cpu: {ratio:.2f}x; same values: {same}")


if __name__ == "__main__":
    main()
