"""Where data, caches and outputs go (analysis.sweeps.paths) and the progress lines (analysis.sweeps.progress)."""
import io

from analysis.sweeps.paths import DATA_DIR, cache_dir, same_json_apart_from, write_if_changed
from analysis.sweeps.progress import Progress


def test_reference_data_is_package_data():
    assert (DATA_DIR / "paper_tables.csv").is_file()
    assert DATA_DIR.parent.name == "analysis"


def test_cache_dir_from_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("TDOA_WORKBENCH_CACHE", str(tmp_path / "c"))
    assert cache_dir("complexity") == tmp_path / "c" / "complexity"
    monkeypatch.delenv("TDOA_WORKBENCH_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "tdoa-workbench"


def test_write_if_changed_keeps_files_whose_results_did_not_change(tmp_path):
    path = tmp_path / "p.json"
    same = same_json_apart_from({"date", "seconds"})
    assert write_if_changed(path, '{"degree": 75, "date": "monday", "t": {"seconds": 1}}\n', same)
    assert not write_if_changed(path, '{"degree": 75, "date": "tuesday", "t": {"seconds": 2}}\n', same)
    assert "monday" in path.read_text()
    assert write_if_changed(path, '{"degree": 74, "date": "tuesday", "t": {"seconds": 2}}\n', same)
    assert write_if_changed(tmp_path / "b", b"x")  # a new file is written
    assert not write_if_changed(tmp_path / "b", b"x")


def test_progress_on_a_pipe_prints_few_lines():
    out = io.StringIO()
    bar = Progress("sweep 1/2", 100, True, "formulations", stream=out)
    for _ in range(100):
        bar.update(1, "9r3s:C2-C9 |B|=75")
    bar.close()
    lines = out.getvalue().splitlines()
    assert lines[0] == "sweep 1/2: 100 formulations" and lines[-1].startswith("sweep 1/2: 100/100 formulations done in")
    assert len(lines) == 5 and "\r" not in out.getvalue()
    quiet = io.StringIO()
    batch = Progress("9r/3s ours sigma=0", 10, True, "trials", stream=quiet, checkpoints=0)
    batch.update(10)
    batch.close()
    assert quiet.getvalue().count("\n") == 1
