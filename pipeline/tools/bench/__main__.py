"""``python -m pipeline.tools.bench [options]``: see ``pipeline.tools.bench``."""

from pipeline.tools.bench.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
