"""Forward runs for the estimators: in parallel on Dask, cached, logged, resumable.

Every estimator asks :class:`Evaluator` for the residuals of a batch of points θ
of the search space; the batch runs as parallel Dask tasks (a ``LocalCluster``
of single-threaded worker processes by default, or an existing cluster at
``scheduler_address``). Each finished run is appended to a JSON-lines log; a
calibration started again with the same log reads it back and skips the runs
already done — the estimators are deterministic, so a resumed search retraces
its steps from the log and goes on where it stopped.

A run that fails (the simulation diverged, a worker died) is a failure, not a
data point: it is logged with ``"status": "failed"`` and its error, never cached
nor replayed by a resume; the estimators see a large residual for it, so they
step away, and when most runs of a batch fail the calibration stops with one
clear error (:class:`~hifumotion.errors.CalibrationFailed`).
"""

from __future__ import annotations

import json
import logging
import os
import warnings
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from hifumotion.console import log
from hifumotion.errors import CalibrationFailed, InputError, brief
from hifumotion.estimation.settings import scheduler_address_problem
from hifumotion.estimation.model import ModelSpec, Parameters, forward_model, run_model, run_snapshot
from hifumotion.estimation.objective import TrainingData, frame_sums_mm, residuals_mm
from hifumotion.estimation.space import SearchSpace


@contextmanager
def _sigint_ignored():
    """SIGINT ignored inside the block (in the main thread; elsewhere signals cannot be set)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _use_threads(threads: int | None) -> None:
    """Numba and MKL threads of a task (1 on a worker: the workers are the parallelism; None
    leaves the process's setting)."""
    if threads is not None:
        import numba

        from hifumotion.creep.linear import set_threads

        numba.set_num_threads(min(int(threads), numba.config.NUMBA_NUM_THREADS))
        set_threads(int(threads))


def forward_residuals(spec: ModelSpec, data: TrainingData, k: Parameters, upto: int | None = None,
                      threads: int | None = 1) -> dict:
    """One forward run (a Dask task): residuals (mm) of the first ``upto`` training frames
    (``threads``: :func:`_use_threads`)."""
    _use_threads(threads)
    n = len(data.frames) if upto is None else int(upto)
    run = run_model(spec, k, int(data.frames[n - 1]))
    r = residuals_mm(run.points_mm, data, n, run.bar_centre_mm)
    return {"residuals_mm": r, "seconds": run.seconds, "steps": run.steps}


def full_run_task(spec: ModelSpec, data: TrainingData, k: Parameters, upto: int, threads: int | None = 1) -> dict:
    """One run of the full model (a Dask task) whose nodes are kept: the residuals (mm) of the
    first ``upto`` training frames, and the run as a reduced model's snapshot (``"snapshot"``)."""
    _use_threads(threads)
    run, snapshot = run_snapshot(spec, k, int(data.frames[upto - 1]))
    r = residuals_mm(run.points_mm, data, upto, run.bar_centre_mm)
    return {"residuals_mm": r, "seconds": run.seconds, "steps": run.steps, "snapshot": snapshot}


def snapshot_task(spec: ModelSpec, scene, threads: int | None = 1):
    """One snapshot run of the spec's reduced model (a Dask task; :meth:`~.model.ModelSpec.snapshot_scenes`)."""
    from hifumotion.creep.scene_run import snapshot_run

    _use_threads(threads)
    return snapshot_run(scene, spec.voxels(), spec.tissue_volume_mm3, spec.settings.creep)


#: Residual (mm) given to a failed run at each point, so an estimator steps away from it.
FAILED_RESIDUAL_MM = 10.0


def check_search_log(path: str | Path) -> Path:
    """Raise :class:`~hifumotion.errors.InputError` unless ``path`` is a readable search log
    (JSON lines of runs; a last line cut short by an interruption is allowed)."""
    from hifumotion.io.files import require_regular_file

    p = require_regular_file(path, "search log (search_log.jsonl)")
    try:
        lines = [ln for ln in p.read_text(encoding="utf-8").splitlines() if ln.strip()]
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read the search log ({brief(exc)})", p) from None
    if not lines:
        raise InputError("is empty; expected the search_log.jsonl of an interrupted calibration", p)
    for number, line in enumerate(lines, 1):
        try:
            rec = json.loads(line)
            ok = isinstance(rec, dict) and {"theta", "upto"} <= set(rec)
        except RecursionError:
            ok = False      # nested thousands of levels: no search log wrote that
        except ValueError:
            ok = number == len(lines) and number > 1    # only the last line may be cut short while written
        if not ok:
            raise InputError(f"line {number} is not a run of a search log (expected JSON with theta, upto, "
                             "residuals_mm)", p)
    return p


def _key(theta: np.ndarray, upto: int, model: str = "") -> tuple:
    """A run's cache key: its model (:attr:`Evaluator.model_tag`), frames and θ."""
    return (model, int(upto)) + tuple(round(float(t), 9) for t in theta)


class Evaluator:
    """Residuals ``r(θ)`` (mm) of the training frames, computed on Dask, cached and logged.

    Parameters
    ----------
    spec, data, space
        The forward model, the observed training contours and the search space.
    log_path
        JSON-lines file of finished runs (read back on start: resume).
    scheduler_address
        An existing Dask scheduler; default a ``LocalCluster`` of ``workers`` processes.
    progress
        ``progress(runs_done, runs_asked)``, called as runs finish.
    """

    def __init__(self, spec: ModelSpec, data: TrainingData, space: SearchSpace, log_path: str | Path | None = None,
                 scheduler_address: str | None = None, workers: int | None = None,
                 progress: Callable[[int, int], None] | None = None):
        self.spec, self.data, self.space = spec, data, space
        self.log_path = Path(log_path) if log_path is not None else None
        self.scheduler_address = scheduler_address
        self.workers = workers or max(1, min(os.cpu_count() or 1, 8))
        self.progress = progress or (lambda done, asked: None)
        self.cache: dict[tuple, np.ndarray] = {}
        self.history: list[dict] = []
        self.runs = 0
        self.failed = 0
        self.run_seconds = 0.0
        self.resumed = 0
        self._client = None
        self._cluster = None
        self._remote = None
        self._cores = 1   # cores a lone run may use: the local cluster's workers' (1 on a remote one)
        # which model the runs are of: "" for the spec's own integrator; for a reduced model, the
        # θ its modes were made around (its runs differ from another reduced model's)
        self.model_tag = ""
        self.reductions: list[dict] = []   # each reduce_around's timings (s)
        # (θ, run) of the full runs whose nodes were kept (reduce_around's and full_runs'), newest
        # first: every reduced model of this spec is made from all of them
        self.snapshots: list[tuple] = []
        # added to every residual returned (mm, ``(n, M)`` of the training frames; :meth:`corrected`)
        self._correction: np.ndarray | None = None
        if self.log_path is not None and self.log_path.is_file():
            self._read_log()

    # -- log ----------------------------------------------------------------
    def _read_log(self) -> None:
        for line in self.log_path.read_text().splitlines():
            try:
                rec = json.loads(line)
                theta = np.asarray(rec["theta"], float)
                r = np.asarray(rec["residuals_mm"], float)
                upto = int(rec["upto"])
            except (ValueError, KeyError, TypeError, RecursionError):
                continue  # a line cut short by an interruption
            if rec.get("status", "ok") != "ok":
                continue  # a failure is not a result: run it again
            self.cache[_key(theta, upto, str(rec.get("model", "")))] = r
            self.history.append(rec)
            self.resumed += 1

    def _log(self, theta, upto, result) -> None:
        k = self.space.parameters(theta)
        rec = {"theta": [float(t) for t in theta], "upto": int(upto), "parameters": k.as_dict(),
               "S_t_mm": frame_sums_mm(result["residuals_mm"]).round(5).tolist(),
               "cost_mm": float(np.abs(result["residuals_mm"]).sum()),
               "seconds": round(float(result["seconds"]), 3), "steps": int(result["steps"]),
               "residuals_mm": np.round(result["residuals_mm"], 5).tolist(),
               "status": "failed" if "error" in result else "ok"}
        if self.model_tag:
            rec["model"] = self.model_tag
        if "error" in result:
            rec["error"] = result["error"]
        self.history.append(rec)
        if self.log_path is not None:
            with open(self.log_path, "a", encoding="utf-8") as fh:
                fh.write(json.dumps(rec) + "\n")

    # -- cluster ------------------------------------------------------------
    @contextmanager
    def cluster(self):
        """Start (or connect to) the Dask cluster for the evaluations inside the block."""
        from dask.distributed import Client, LocalCluster

        if self.scheduler_address:
            problem = scheduler_address_problem(self.scheduler_address)
            if problem:
                raise InputError(problem, "scheduler_address")
            try:
                self._client = Client(self.scheduler_address, timeout="20s")
            except (OSError, ValueError, TimeoutError) as exc:
                raise InputError(f"cannot reach the Dask scheduler ({brief(exc)})", self.scheduler_address) from None
        else:
            # the workers start with Ctrl-C ignored (an ignored signal stays ignored in a spawned
            # process): a Ctrl-C in the terminal reaches the whole process group, and each worker
            # would print its own traceback while this process closes them anyway
            with _sigint_ignored(), warnings.catch_warnings():
                # another cluster on this machine holds Dask's default HTTP port: its scheduler
                # takes another, and that is no news for the user
                warnings.filterwarnings("ignore", message="Port .* is already in use")
                self._cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                             dashboard_address=None,
                                             silence_logs=logging.WARNING if log.isEnabledFor(logging.DEBUG)
                                             else logging.CRITICAL)
            self._client = Client(self._cluster)
            self._cores = self.workers
        try:
            self._remote = self._client.scatter([self.spec, self.data], broadcast=True)
            yield self
        finally:
            self._client.close()
            if self._cluster is not None:
                self._cluster.close()
            self._client = self._cluster = self._remote = None
            self._cores = 1

    @contextmanager
    def sibling(self, spec: ModelSpec):
        """An evaluator of another model on the same data and this one's running cluster."""
        other = Evaluator(spec, self.data, self.space, workers=self.workers)
        other._client = self._client
        other._cores = self._cores
        other._remote = self._client.scatter([spec, self.data], broadcast=True)
        try:
            yield other
        finally:
            self.runs += other.runs
            self.failed += other.failed
            self.run_seconds += other.run_seconds
            other._client = other._remote = None

    @contextmanager
    def corrected(self, correction: np.ndarray | None):
        """Inside the block :meth:`residuals` returns each run's residuals plus ``correction`` (mm,
        the training frames' ``(n, M)``; None: none): a model made to agree with another at one
        point. Cached runs are kept uncorrected."""
        kept, self._correction = self._correction, None if correction is None else np.asarray(correction, float)
        try:
            yield self
        finally:
            self._correction = kept

    @contextmanager
    def within(self, space: SearchSpace):
        """Inside the block the evaluations and searches see ``space`` (narrower bounds: a reduced
        model's trust region); the runs and their cache are the same."""
        whole, self.space = self.space, space
        try:
            yield self
        finally:
            self.space = whole

    def reduce_around(self, theta: np.ndarray, upto: int | None = None, new_runs: bool = True) -> float:
        """Make the spec's reduced model around ``θ`` (its snapshot runs in parallel on the cluster,
        the model here), send it to the workers and run on it from now on; seconds taken.
        Its modes are those of every full run kept so far (:attr:`snapshots`) and, with
        ``new_runs``, of the spec's snapshot scenes at ``θ`` run now; without, ``θ``'s own run must
        be among the kept ones already (:meth:`full_runs`). Nothing to do (0 s) unless the spec's
        integrator is a reduced one."""
        import time

        if not forward_model(self.spec).is_reduced:
            return 0.0
        started = time.perf_counter()
        n = len(self.data.frames) if upto is None else int(upto)
        last = int(self.data.frames[n - 1])
        theta = np.clip(np.asarray(theta, float), self.space.lower, self.space.upper)
        k = self.space.parameters(theta)
        runs = []
        if new_runs:
            scenes = self.spec.snapshot_scenes(k, last)
            threads = max(1, self._cores // len(scenes))
            futures = [self._client.submit(snapshot_task, self._remote[0], scene, threads, pure=False)
                       for scene in scenes]
            try:
                runs = self._client.gather(futures)
            except InputError:
                raise
            except Exception as exc:
                raise CalibrationFailed(f"the reduced model's snapshot runs at {k} failed ({brief(exc)})") from None
        elif not self.snapshots:
            raise RuntimeError("a reduced model without new runs needs a kept full run (full_runs)")
        # the run at θ first: the model's settled state is its first snapshot's
        here = [s for s in self.snapshots if np.array_equal(s[0], theta)]
        self.snapshots = [(tuple(theta), r) for r in runs] + here + [s for s in self.snapshots
                                                                    if not np.array_equal(s[0], theta)]
        ran = time.perf_counter()
        model = self.spec.adopt_reduced(k, last, [r for _, r in self.snapshots])
        made = time.perf_counter()
        self._remote = self._client.scatter([self.spec, self.data], broadcast=True)
        # a model made again at the same θ from more runs is another model: its runs are not cached
        self.model_tag = "reduced@" + ",".join(f"{x:.9g}" for x in theta) + f"/{len(self.snapshots)}"
        done = time.perf_counter()
        self.reductions.append({"snapshot_runs_s": ran - started, "model_s": made - ran, "sent_s": done - made,
                                "snapshot_run_s": [float(r.stats.get("seconds", 0.0)) for r in runs],
                                "snapshots": len(self.snapshots),
                                "modes": int(model.basis.size)})
        return done - started

    def snapshot_runs(self, spec: ModelSpec, k: Parameters, last_frame: int) -> list:
        """The full runs ``spec``'s reduced model around ``k`` is made from (its
        :meth:`~.model.ModelSpec.snapshot_scenes` to ``last_frame``), in parallel on the cluster's
        cores; not counted among the search's runs."""
        scenes = spec.snapshot_scenes(k, last_frame)
        spec.voxels()        # made once here, sent with the spec
        remote = self._client.scatter(spec, broadcast=True)
        threads = max(1, self._cores // len(scenes))
        futures = [self._client.submit(snapshot_task, remote, scene, threads, pure=False) for scene in scenes]
        return self._client.gather(futures)

    def full_runs(self, thetas: list[np.ndarray], upto: int | None = None) -> list[np.ndarray]:
        """Residuals (mm) of runs of the full model at each ``θ``, in parallel on the cluster's cores,
        one thread each (uncached, logged as model ``"full"``); their nodes are kept (:attr:`snapshots`) for the
        next reduced model. A run that fails gives :data:`FAILED_RESIDUAL_MM` everywhere."""
        n = len(self.data.frames) if upto is None else int(upto)
        thetas = [np.clip(np.asarray(t, float), self.space.lower, self.space.upper) for t in thetas]
        # one thread a run, always: a run on two threads is not bitwise repeatable (its sums in
        # another order), and a near-stick amplifies the last digits into another fit; two threads
        # made a 1,000-particle slide only 1.2× faster (docs/decisions.md, "Each reduced fit checked by the full model")
        futures = [self._client.submit(full_run_task, self._remote[0], self._remote[1], self.space.parameters(t), n,
                                       1, pure=False) for t in thetas]
        out = []
        for theta, future in zip(thetas, futures):
            try:
                result = future.result()
                self.snapshots.insert(0, (tuple(theta), result.pop("snapshot")))
            except InputError:
                raise
            except Exception as exc:
                result = self._failed(n, exc)
            result["residuals_mm"] = np.asarray(result["residuals_mm"], float)
            tag, self.model_tag = self.model_tag, "full"
            try:
                self._log(theta, n, result)
            finally:
                self.model_tag = tag
            self.runs += 1
            self.run_seconds += float(result["seconds"])
            out.append(result["residuals_mm"])
        return out

    def _failed(self, n: int, exc: Exception) -> dict:
        """A run that blew up, counted: :data:`FAILED_RESIDUAL_MM` at every point of ``n`` frames,
        so an estimator steps away from it."""
        self.failed += 1
        return {"residuals_mm": np.full((n, self.data.width(len(self.spec.points_mm))), FAILED_RESIDUAL_MM),
                "seconds": 0.0, "steps": 0, "error": brief(exc)}

    # -- evaluation -----------------------------------------------------------
    def residuals(self, thetas: Iterable[np.ndarray], upto: int | None = None) -> list[np.ndarray]:
        """``(n, M)`` residuals (mm) for each θ (runs missing from the cache go to Dask together)."""
        n = len(self.data.frames) if upto is None else int(upto)
        thetas = [np.clip(np.asarray(t, float), self.space.lower, self.space.upper) for t in thetas]
        missing = {}
        for t in thetas:
            key = _key(t, n, self.model_tag)
            if key not in self.cache and key not in missing:
                missing[key] = t
        if missing:
            keys = list(missing)
            results = self._submit([self.space.parameters(missing[k]) for k in keys], n)
            failed = {}
            for key, result in zip(keys, results):
                self._log(missing[key], n, result)
                if "error" in result:
                    failed[key] = result["residuals_mm"]
                else:
                    self.cache[key] = result["residuals_mm"]
            keys = [_key(t, n, self.model_tag) for t in thetas]
            return [self._corrected(failed[key] if key in failed else self.cache[key]) for key in keys]
        return [self._corrected(self.cache[_key(t, n, self.model_tag)]) for t in thetas]

    def _corrected(self, r: np.ndarray) -> np.ndarray:
        """``r`` plus the correction in force (:meth:`corrected`) on its frames."""
        if self._correction is None:
            return r
        return r + self._correction[:len(r)]

    def _submit(self, ks: list[Parameters], n: int) -> list[dict]:
        """Run the parameter sets on the cluster; results in the order asked."""
        from dask.distributed import as_completed

        if self._client is None:
            raise RuntimeError("the Evaluator needs its cluster: use `with evaluator.cluster():`")
        spec_f, data_f = self._remote
        # a batch smaller than the local cluster (the space mapping's lone runs of the final model)
        # leaves cores idle: its runs take them as MKL and Numba threads
        threads = max(1, self._cores // max(len(ks), 1))
        futures = {self._client.submit(forward_residuals, spec_f, data_f, k, n, threads, pure=False): i
                   for i, k in enumerate(ks)}
        results: list[dict] = [{}] * len(ks)
        for done, fut in enumerate(as_completed(futures), 1):
            try:
                result = fut.result()
            except InputError:
                raise
            except Exception as exc:  # a run that blew up is a bad parameter set, not the end of the fit
                result = self._failed(n, exc)
                log.debug("forward run with %s failed: %s", ks[futures[fut]], brief(exc))
            result["residuals_mm"] = np.asarray(result["residuals_mm"], float)
            results[futures[fut]] = result
            self.runs += 1
            self.run_seconds += float(result["seconds"])
            self.progress(done, len(ks))
        failures = sum("error" in r for r in results)
        if len(ks) >= 2 and failures > len(ks) / 2:
            first = next(r["error"] for r in results if "error" in r)
            raise CalibrationFailed(f"{failures} of {len(ks)} forward runs failed (first: {first}); the model "
                                    "cannot run near these parameters — check the observation and the settings")
        return results

    def parameter_runs(self, ks: list[Parameters], upto: int | None = None) -> list[np.ndarray]:
        """Residuals of parameter sets outside the search space's coordinates (not cached)."""
        n = len(self.data.frames) if upto is None else int(upto)
        return [r["residuals_mm"] for r in self._submit(list(ks), n)]

    def one(self, theta: np.ndarray, upto: int | None = None) -> np.ndarray:
        return self.residuals([theta], upto)[0]


__all__ = ["Evaluator", "forward_residuals", "check_search_log", "FAILED_RESIDUAL_MM"]
