"""``python -m pipeline.report [overrides]``: run the report stage (Hydra)."""

from pipeline.report.stage import main

if __name__ == "__main__":
    main()
