#!/usr/bin/python3
"""Cross-check rigtwin's frictional contact solutions with Siconos' fc3d solvers.

Reads one or more rigtwin contact-problem files (.rtcp, layout documented in
src/contact/problem_io.rs and repeated below), solves every problem with
Siconos numerics' fc3d nonsmooth Gauss-Seidel (NSGS) and, with --solvers, further
fc3d solvers (nsn_ac: nonsmooth Newton on Alart-Curnier, nsn_fb: on
Fischer-Burmeister, through fc3d_driver), and reports per problem
the relative difference between Siconos' solution and the solution rigtwin
stored in the record, plus Siconos' own error measure of both solutions and
the wall time of the Siconos solve alone.

Conventions: Siconos solves u = M r + q, r in K = {||r_t|| <= mu r_n},
u + mu ||u_t|| e_n in K* and r . (u + mu ||u_t|| e_n) = 0, with per contact
the components (normal, t1, t2). That is rigtwin's gamma = W lambda + c,
-gamma in N_C(lambda), C = R+ x Disk(mu lambda_n) with M = W, q = c,
r = lambda, u = gamma.

Record layout (little-endian; d = 3 n):
  b"RTCP", u32 version (1), u32 n, u32 flags (bit 0: solution follows),
  u32 label_len, label (UTF-8), f64 W[d*d] row-major, f64 c[d], f64 mu[n],
  [f64 lambda[d], f64 gamma[d]] if flags & 1.

Usage:
  /usr/bin/python3 tests/siconos/solve_fc3d.py FILE.rtcp [...] [--json OUT]
      [--tol 1e-12] [--max-iter 100000] [--repeat 5] [--solvers nsgs,nsn_ac]

The top-level entries of each problem are NSGS's; "solvers" holds every solver's
info, iterations, error, time and differences to rigtwin's stored solution.

Needs python3-siconos (Debian/Ubuntu package; importable by /usr/bin/python3)
and numpy. Exit status: 0 when every problem was solved by Siconos (info 0),
1 otherwise, 2 on bad input, 3 when siconos cannot be imported.
"""

import argparse
import json
import struct
import sys
import time

import numpy as np

MAGIC = b"RTCP"
VERSION = 1


def read_records(path):
    """Yield (label, W, c, mu, lambda or None, gamma or None) for every record."""
    with open(path, "rb") as f:
        data = f.read()
    pos = 0
    index = 0
    while pos < len(data):
        start = pos
        if data[pos:pos + 4] != MAGIC:
            raise ValueError(f"{path}: record {index} at byte {start}: bad magic "
                             f"{data[pos:pos + 4]!r}, expected {MAGIC!r}")
        if len(data) < pos + 20:
            raise ValueError(f"{path}: record {index} at byte {start}: truncated header")
        version, n, flags, label_len = struct.unpack_from("<4I", data, pos + 4)
        if version != VERSION:
            raise ValueError(f"{path}: record {index}: version {version}, expected {VERSION}")
        pos += 20
        label = data[pos:pos + label_len].decode("utf-8")
        pos += label_len
        d = 3 * n

        def take(count, what):
            nonlocal pos
            end = pos + 8 * count
            if end > len(data):
                raise ValueError(f"{path}: record {index}: truncated in {what}")
            v = np.frombuffer(data, dtype="<f8", count=count, offset=pos).astype(np.float64)
            pos = end
            return v

        w = take(d * d, "W").reshape(d, d)
        c = take(d, "c")
        mu = take(n, "mu")
        lam = gam = None
        if flags & 1:
            lam = take(d, "lambda")
            gam = take(d, "gamma")
        yield label, w, c, mu, lam, gam
        index += 1


def rel(a, b, scale):
    """||a - b|| / scale (0 when both vanish)."""
    num = float(np.linalg.norm(a - b))
    if num == 0.0:
        return 0.0
    return num / scale if scale > 0.0 else float("inf")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="+", help="rigtwin .rtcp problem files")
    ap.add_argument("--json", help="write per-problem results as JSON to this path")
    ap.add_argument("--tol", type=float, default=1e-12, help="Siconos NSGS tolerance")
    ap.add_argument("--max-iter", type=int, default=100000, help="Siconos NSGS iteration limit")
    ap.add_argument("--repeat", type=int, default=5,
                    help="solve each problem this many times; the minimum time is reported")
    ap.add_argument("--solvers", default="nsgs",
                    help="comma-separated fc3d solvers: nsgs, nsn_ac, nsn_fb (nsgs always runs)")
    args = ap.parse_args()

    try:
        import siconos.numerics as sn
    except ImportError as e:  # pragma: no cover - environment dependent
        print(f"solve_fc3d.py: cannot import siconos.numerics ({e}); "
              "install python3-siconos and run with /usr/bin/python3", file=sys.stderr)
        return 3

    results = []
    all_ok = True
    try:
        records = [(path, rec) for path in args.files for rec in read_records(path)]
    except (OSError, ValueError, UnicodeDecodeError) as e:
        print(f"solve_fc3d.py: {e}", file=sys.stderr)
        return 2

    for i, (path, (label, w, c, mu, lam, gam)) in enumerate(records):
        n = len(mu)
        problem = sn.FrictionContactProblem(3, np.ascontiguousarray(w), c.copy(), mu.copy())
        best = float("inf")
        for _ in range(max(1, args.repeat)):
            options = sn.SolverOptions(sn.SICONOS_FRICTION_3D_NSGS)
            options.iparam[sn.SICONOS_IPARAM_MAX_ITER] = args.max_iter
            options.dparam[sn.SICONOS_DPARAM_TOL] = args.tol
            r = np.zeros(3 * n)
            u = np.zeros(3 * n)
            t0 = time.perf_counter()
            info = sn.fc3d_nsgs(problem, r, u, options)
            best = min(best, time.perf_counter() - t0)
        iterations = int(options.iparam[sn.SICONOS_IPARAM_ITER_DONE])
        error = float(options.dparam[sn.SICONOS_DPARAM_RESIDU])
        all_ok &= info == 0
        entry = {
            "file": path,
            "index": i,
            "label": label,
            "n_pairs": n,
            "siconos_info": int(info),
            "siconos_iterations": iterations,
            "siconos_error": error,
            "siconos_time_s": best,
            "siconos_r": r.tolist(),
        }
        norm_q = float(np.linalg.norm(c))
        if lam is not None:
            # Siconos' own error measure of rigtwin's solution (same normalisation as its solve).
            eval_options = sn.SolverOptions(sn.SICONOS_FRICTION_3D_NSGS)
            gam_check = w @ lam + c
            _, rig_err = sn.fc3d_compute_error(problem, lam.copy(), gam_check.copy(),
                                               args.tol, eval_options, norm_q)
            force_scale = max(float(np.linalg.norm(r)), float(np.linalg.norm(lam)))
            velocity_scale = max(float(np.linalg.norm(u)), norm_q)
            entry.update({
                "rel_diff_lambda": rel(lam, r, force_scale),
                "rel_diff_gamma": rel(gam, u, velocity_scale),
                "rigtwin_gamma_consistency": rel(gam, gam_check, velocity_scale),
                "rigtwin_error_by_siconos": float(rig_err),
            })
        entry["solvers"] = {"nsgs": {
            "info": entry["siconos_info"], "iterations": iterations, "error": error,
            "time_s": best, "rel_diff_lambda": entry.get("rel_diff_lambda"),
            "rel_diff_gamma": entry.get("rel_diff_gamma")}}
        for name in [x for x in args.solvers.split(",") if x and x != "nsgs"]:
            solver_id = {"nsn_ac": sn.SICONOS_FRICTION_3D_NSN_AC,
                         "nsn_fb": sn.SICONOS_FRICTION_3D_NSN_FB}[name]
            best_x = float("inf")
            for _ in range(max(1, args.repeat)):
                opts = sn.SolverOptions(solver_id)
                opts.iparam[sn.SICONOS_IPARAM_MAX_ITER] = args.max_iter
                opts.dparam[sn.SICONOS_DPARAM_TOL] = args.tol
                rx = np.zeros(3 * n)
                ux = np.zeros(3 * n)
                t0 = time.perf_counter()
                info_x = sn.fc3d_driver(problem, rx, ux, opts)
                best_x = min(best_x, time.perf_counter() - t0)
            sub = {"info": int(info_x),
                   "iterations": int(opts.iparam[sn.SICONOS_IPARAM_ITER_DONE]),
                   "error": float(opts.dparam[sn.SICONOS_DPARAM_RESIDU]),
                   "time_s": best_x}
            if lam is not None:
                sub["rel_diff_lambda"] = rel(lam, rx, max(float(np.linalg.norm(rx)),
                                                           float(np.linalg.norm(lam))))
                sub["rel_diff_gamma"] = rel(gam, ux, max(float(np.linalg.norm(ux)), norm_q))
            all_ok &= info_x == 0
            entry["solvers"][name] = sub
        results.append(entry)

    print(f"{'#':>3} {'pairs':>5} {'info':>4} {'iter':>6} {'sic. err':>9} {'rig err':>9} "
          f"{'d lambda':>9} {'d gamma':>9} {'time ms':>8}  label")
    for e in results:
        print(f"{e['index']:>3} {e['n_pairs']:>5} {e['siconos_info']:>4} "
              f"{e['siconos_iterations']:>6} {e['siconos_error']:>9.2e} "
              f"{e.get('rigtwin_error_by_siconos', float('nan')):>9.2e} "
              f"{e.get('rel_diff_lambda', float('nan')):>9.2e} "
              f"{e.get('rel_diff_gamma', float('nan')):>9.2e} "
              f"{1e3 * e['siconos_time_s']:>8.3f}  {e['label']}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"tolerance": args.tol, "max_iter": args.max_iter, "problems": results}, f)
    return 0 if all_ok else 1


if __name__ == "__main__":
    sys.exit(main())
