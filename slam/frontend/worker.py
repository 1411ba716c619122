"""Scan matching beside reading: KISS-ICP in a second process.

KISS-ICP is the largest part of mapping a run, and it needs nothing but the
laser scans (and, with ``frontend.initial_guess: odometry``, the odometry).
:class:`BackgroundScanMatching` starts a child process (see
:mod:`slam.processes.background`) before the run is read; the child imports KISS-ICP
and waits. The reader hands over the scans as soon as they are decoded (a
ROS bag's scan topic is read first): a thread here puts them through
KISS-ICP's first half, which depends on each scan alone
(:mod:`slam.frontend.scan_prep`), and feeds the child a chunk at a time as it takes
them, while this process reads the other topics, imports the back-end and
validation, and writes what does not depend on the estimate. The child
registers them. :meth:`BackgroundScanMatching.result` then waits for the
poses. They are the same as :func:`slam.frontend.kiss.run_frontend`'s in this
process: KISS-ICP's own calls, in its order, on the same scans.
"""

from __future__ import annotations

import threading
import time

from slam.processes.background import Forked, Inbox, start
from slam.config import FrontendConfig
from slam.frontend.kiss import FrontendResult, odometry_guesses, run_frontend
from slam.recording import Scans, Trajectory
from slam.frontend.scan_prep import PreparedHeader, prepared_chunks, register_prepared

def _register(inbox: Inbox, config: FrontendConfig, progress: bool) -> FrontendResult | None:
    import kiss_icp.kiss_icp  # noqa: F401 - while the parent reads the scans

    sent = inbox()
    if sent is None:  # no scans after all
        return None
    if isinstance(sent, PreparedHeader):  # KISS-ICP's first half is done in the parent
        return register_prepared(sent, inbox, config, progress)
    scans, odometry = sent
    return run_frontend(scans, config, progress=progress, odometry=odometry)


class BackgroundScanMatching:
    """KISS-ICP on the scans it is given (:meth:`give`), in a second process
    when ``concurrent`` (else when :meth:`result` is asked for)."""

    def __init__(self, config: FrontendConfig, progress: bool = False, concurrent: bool = True):
        self.config = config
        self.needs_odometry = config.initial_guess == "odometry"
        self.worker = start("scan matching", _register, config, progress, concurrent=concurrent)
        if isinstance(self.worker, Forked):
            import kiss_icp.kiss_icp  # noqa: F401 - for KISS-ICP's first half here, before the scans arrive
        self.given = False
        self.feeder: threading.Thread | None = None
        self.feed_error: BaseException | None = None

    def give(self, scans: Scans | None, odometry: Trajectory | None = None) -> None:
        """The scans to register (and the odometry for the guesses), once.
        To a second process they go through KISS-ICP's first half here
        (:mod:`slam.frontend.scan_prep`), a chunk at a time."""
        if self.given:
            return
        self.given = True
        odometry = odometry if self.needs_odometry else None
        if scans is None or not isinstance(self.worker, Forked):
            self.worker.send(None if scans is None else (scans, odometry))
            return
        # The pipe holds 64 KiB: a thread feeds it at the child's pace while
        # this one reads on.
        self.feeder = threading.Thread(target=self._feed, args=(scans, odometry), name="gslam scan feeder", daemon=True)
        self.feeder.start()

    def _feed(self, scans: Scans, odometry: Trajectory | None) -> None:
        try:
            self.worker.send(PreparedHeader(len(scans), scans.range_max))
            for chunk in prepared_chunks(scans, self.config, odometry_guesses(scans.t, self.config, odometry)):
                self.worker.send(chunk)
            self.worker.send(None)
        except BaseException as e:  # noqa: BLE001 - raised by result()
            self.feed_error = e

    def result(self, scans: Scans) -> tuple[FrontendResult | None, float]:
        """The registration of ``scans`` (the recording's, whose times the
        poses get) and the seconds spent waiting for it here."""
        start_wait = time.perf_counter()
        self._join_feeder()
        found = self.worker.result()
        waited = time.perf_counter() - start_wait
        if found is None:
            return None, waited
        p = found.poses
        poses = Trajectory(t=scans.t.copy(), x=p.x, y=p.y, yaw=p.yaw)
        return FrontendResult(poses=poses, n_points=found.n_points, time_s=found.time_s), waited

    def _join_feeder(self) -> None:
        if self.feeder is not None:
            self.feeder.join()
            self.feeder = None
        if self.feed_error is not None:
            error, self.feed_error = self.feed_error, None
            self.worker.close()
            raise error

    def close(self) -> None:
        self.worker.close()  # a feeder still sending meets a closed pipe and ends
        if self.feeder is not None:
            self.feeder.join()
            self.feeder = None
