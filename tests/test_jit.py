from trafficsim import jit


def test_kernel_cache_folder_changes_with_any_source_edit(tmp_path, monkeypatch):
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")
    monkeypatch.setattr(jit, "_PACKAGE", tmp_path)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    first = jit.kernel_cache_dir()
    assert first.parent == tmp_path / "cache" and first == jit.kernel_cache_dir()
    (tmp_path / "sub" / "b.py").write_text("y = 3\n")  # an edit in a called module
    assert jit.kernel_cache_dir() != first


def test_kernel_folders_of_other_sources_are_deleted_once_unused_for_a_month(tmp_path):
    import os

    day = 86400.0
    now = 1e9
    current, recent, stale = (tmp_path / f"kernels-{k}" for k in ("cur", "recent", "stale"))
    other = tmp_path / "notes"  # not a kernel folder: never touched
    for folder, age_days in ((current, 400), (recent, 29), (stale, 31), (other, 400)):
        folder.mkdir()
        (folder / "index.nbi").write_text("x")
        os.utime(folder, (now - age_days * day, now - age_days * day))
    jit.prune_stale(current, now)
    assert current.is_dir() and current.stat().st_mtime == now  # in use: marked, kept
    assert recent.is_dir() and other.is_dir()
    assert not stale.exists()
