"""Stage functions `run_<stage>(cfg, out_dir) -> list[Path]`, called by the CLI (through Hydra) and by the tests."""
