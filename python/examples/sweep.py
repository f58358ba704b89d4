"""Monte Carlo sweep: 1,000 SITL flights under randomized wind, gusts and weak rotors, flown
with multiprocessing and again on Ray; prints the success rate and the RMSE quantiles of each
and checks that both give the same numbers.

    python python/examples/sweep.py                      # 1,000 flights, both backends, 2 workers
    python python/examples/sweep.py --flights 200 --backend ray --workers 8
    python python/examples/sweep.py --address auto       # an existing Ray cluster, no new code

On a cluster, `ray.init(address=...)` is the only change: the tasks and the numbers stay.
"""

import argparse
import time

from hamflight import montecarlo as mc


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--flights", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=2024)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--controller", default="adaptive")
    ap.add_argument("--backend", default="both", choices=["both", "multiprocessing", "ray", "serial"])
    ap.add_argument("--address", default=None, help="Ray cluster address (default: a local Ray with --workers CPUs)")
    args = ap.parse_args()

    draws = mc.draw(args.flights, args.seed)
    summaries = {}
    backends = ["multiprocessing", "ray"] if args.backend == "both" else [args.backend]
    for backend in backends:
        if backend == "ray" and args.address:
            import ray

            ray.init(address=args.address)
        t0 = time.perf_counter()
        res = mc.run(draws, backend=backend, workers=args.workers, controller=args.controller)
        wall = time.perf_counter() - t0
        summaries[backend] = (res, mc.summarize(res))
        print(f"{backend:>15} ({wall:.1f} s): {mc.summary_text(summaries[backend][1])}")
    if len(summaries) == 2:
        (ra, sa), (rb, sb) = summaries.values()
        same = ra == rb
        print("identical per-flight results on both backends:", same)
        raise SystemExit(0 if same else 1)


if __name__ == "__main__":  # multiprocessing's spawn re-imports this file
    main()
