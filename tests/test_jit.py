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
