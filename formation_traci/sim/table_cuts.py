"""When a run's tables are cut into part files and what of them is on disk (the Recorder's
half that run.json's progress and the end of a run rely on, sim/recorder.py): every
``steps_per_chunk`` steps every table is cut at the same time, progress is reported only up
to the time every table is on disk, and the end writes the rest without raising."""
from __future__ import annotations


class TableCuts:
    """Mixed into sim/recorder.py Recorder: needs its ``tables()``, ``ssm``,
    ``_fixed_tables``, ``_latest``, ``_reported`` and ``steps_per_chunk``."""

    def end_step(self, k: int, t: float, report=None) -> None:
        """Every row of step ``k`` (time t [s]) is recorded; every ``steps_per_chunk`` steps every
        table is cut at t, so after a crash all of them are readable up to the same time.
        ``report(t_done)`` is called when every table is on disk up to a later time
        (:meth:`written_up_to`; run.json's progress). At the step before a cut the parts of
        the last cut are awaited and reported (a table whose buffer is full writes its part
        while the cut step is recorded), so no table is ever more than one part ahead of what
        was reported, however far the writer threads lag (a busy machine)."""
        if (k + 2) % self.steps_per_chunk == 0:
            for table in self.tables().values():
                table.wait()  # the last cut on disk (the writers are normally done long before)
        self._report(report)
        if (k + 1) % self.steps_per_chunk == 0:
            if self.ssm is not None:
                self.ssm.update()
            for table in self.tables().values():
                table.flush(mark=t)

    def _report(self, report) -> None:
        if report is not None:
            done = self.written_up_to()
            if done is not None:
                report(done)

    def written_up_to(self) -> float | None:
        """Time [s] up to which every table is on disk, if it moved on since the last call
        (else None): progress reported from it is never ahead of the data."""
        if not any([tb.news for tb in self._fixed_tables]) and (
                self.ssm is None or self.ssm.table is None or not self.ssm.table.news):
            return None  # no part completed since the last call: nothing moved on
        tables = self.tables()
        for name, table in tables.items():
            done = table.written_up_to()
            if done is not None:
                self._latest[name] = done
        if len(self._latest) < len(tables) or any(n not in self._latest for n in tables):
            return None
        t = min(self._latest[n] for n in tables)
        if t <= self._reported:
            return None
        self._reported = t
        return t

    def on_disk(self) -> dict:
        """What each table has on disk: part files, rows and the time [s] it is complete to."""
        return {name: {"parts": tb.parts_on_disk, "rows": tb.rows_on_disk, "complete_to_s": tb.last_on_disk}
                for name, tb in self.tables().items()}

    def flush(self, t_end: float | None = None) -> list[tuple[str, BaseException]]:
        """End of the run: write what is buffered; empty tables get a zero-row part. Never
        raises: returns (table, error) for each table that could not be written whole (e.g.
        disk full); the parts written before stay readable."""
        errors = []
        if self.ssm is not None:
            try:
                self.ssm.update()
            except Exception as exc:
                errors.append(("ssm", exc))
        for name, table in self.tables().items():
            try:
                if t_end is not None:
                    table.flush(mark=t_end)
                table.close()
            except Exception as exc:
                errors.append((name, exc))
        return errors
