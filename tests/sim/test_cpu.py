"""The haptic core's idle limit is set for a run and restored after it, and never required."""

from sim.runtime.cpu import IdlePolling


def test_the_limit_is_set_inside_and_restored_after(tmp_path):
    power = tmp_path / "cpu3" / "power"
    power.mkdir(parents=True)
    limit = power / "pm_qos_resume_latency_us"
    limit.write_text("0\n")
    with IdlePolling(3, root=tmp_path) as polling:
        assert polling.active and limit.read_text() == "n/a"
    assert limit.read_text() == "0" and not polling.active


def test_the_limit_is_restored_when_the_run_fails(tmp_path):
    power = tmp_path / "cpu0" / "power"
    power.mkdir(parents=True)
    (power / "pm_qos_resume_latency_us").write_text("25")
    try:
        with IdlePolling(0, root=tmp_path):
            raise RuntimeError("a layer failed")
    except RuntimeError:
        pass
    assert (power / "pm_qos_resume_latency_us").read_text() == "25"


def test_without_the_file_nothing_happens(tmp_path):
    with IdlePolling(7, root=tmp_path) as polling:
        assert not polling.active
    assert not (tmp_path / "cpu7").exists()


def test_the_real_run_leaves_the_machine_as_it_found_it():
    """A real-time run sets the haptic core's limit (root here) and puts the old value back."""
    import os

    from sim.runtime.cpu import SYSFS_CPUS

    last = max(os.sched_getaffinity(0))
    path = SYSFS_CPUS / f"cpu{last}" / "power" / "pm_qos_resume_latency_us"
    before = path.read_text()
    seen = []
    with IdlePolling(last) as polling:
        seen.append((polling.active, path.read_text().strip()))
    assert path.read_text() == before
    assert seen == [(True, "n/a")]


def test_steal_is_read_per_core_in_seconds(tmp_path):
    import os

    from sim.runtime.cpu import stolen_seconds

    ticks = os.sysconf("SC_CLK_TCK")
    stat = tmp_path / "stat"
    stat.write_text(
        "cpu  10554 0 4196 22630 517 0 78 22 0 0\n"
        "cpu0 2295 0 1198 15432 51 0 12 6 0 0\n"
        f"cpu1 8259 0 2998 7197 465 0 65 {3 * ticks} 0 0\n"
        "intr 1 2 3\n"
    )
    assert stolen_seconds(stat) == {0: 6 / ticks, 1: 3.0}
    assert stolen_seconds(tmp_path / "missing") == {}
