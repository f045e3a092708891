"""The report stage: gather the latest artifacts into ``reports/`` (tables, figures, README).

``report(cfg)`` is a pure function of the config and its upstream artifacts. It writes the
versioned artifact ``data/report/<version>/``::

    manifest.json                 what produced it (see pipeline.artifacts)
    README.md                     the report (Markdown; links are relative to this folder)
    log.rrd, log.mcap             Rerun and MCAP logs of the tables (one text entry each)
    tables/dataset_splits.csv     per split: scenes, boxes, removed boxes, settle steps
    tables/box_types.csv          per box type: boxes, mean visible area in the mask
    figures/sample_depth.png      ``report.num_sample_images`` test depth images + instance masks
    figures/boxes_per_scene.png   histogram of boxes per scene, all splits
    tables/label_classes.csv      per split and level (hand / robot): grasp points per class
    tables/label_ng_reasons.csv   per NG reason: grasp points per split
    tables/surface_accuracy.csv   per split: detected surfaces vs. the simulator's true faces
    figures/labels_sample.png     test depth images with their grasp points coloured by class
    tables/table1_precision.csv   Table 1: precision top 1 / top 1 % / 5 % / 10 %, paper and ours
    tables/threshold_calibration.csv  the validation curve that chose th (Eq. 3)
    tables/training_curve.csv     the training and validation loss per epoch
    figures/pr_curve.png          the DCNN's precision–recall curve on the test split
    tables/table2_centre_distance.csv  Table 2: optimal grasp points near surface centres
    tables/planning_time.csv      planning time per image of each planner (wall-clock)
    tables/run_time.csv           per stage: the wall-clock time its reported artifacts took
    figures/table2_curve.png      Table 2 over the radius (pixels)
    figures/fig10_planners.png    every planner's optimal grasp point on test images (Fig. 10)
    tables/table3_*.csv           Table 3: success, failures, path deviation, timing (wall-clock)
    figures/servo_convergence.png  the servo's error over simulated time
    tables/ablation.csv           the execution ablation
    tables/unseen_table1.csv, unseen_table2.csv  Tables 1 and 2 on unseen box sizes
    tables/robustness_*.csv       the robustness study (sensor model, Tables 1–2 per input,
                                  closed-loop variants, Sec. 8.4's policies, failures)
    figures/robustness_depth.png  ideal, sensor-model and filtered depth of one test image

and then publishes README.md, figures/ and tables/ into ``paths.reports`` (``<root>/reports/``),
replacing those files one by one and leaving other files there alone (``publish``).

The report is made of sections, one module each (``section.Section``): each resolves and checks
one upstream artifact, makes its tables and figures and writes its part of the README.

    dataset.py      the generation artifact (``report.generate_version``; required)
    labels.py       the label artifact (``report.label_version``); must be made from that
                    generation artifact
    training.py     Table 1 and the threshold calibration, from the train artifact
                    (``report.train_version``, under ``paths.models``); must have been trained
                    on that label artifact
    baseline.py     Table 2, from the baseline artifact (``report.baseline_version``); must match
                    the generation and the train artifact
    closed_loop.py  Table 3, from the evaluation artifact (``report.evaluate_version``)
    ablation.py     the ablation artifact (``report.ablation_version``)
    unseen.py       the unseen-size artifact (``report.unseen_version``)
    robustness.py   the robustness artifact (``report.robustness_version``)

Every section but the dataset's is optional: its version defaults to the latest artifact, and
without one the README says that the stage has not run and its files are left out; a named
version that does not exist, or an artifact that does not match, is an error
(``upstream.resolve_upstream``). ``stage.report`` loops over the sections; ``tables.Table``
writes a table as Markdown and CSV; ``figures`` draws the figures; ``readme`` assembles the
README. The labelling throughput and the training timings are run-dependent, so they stay in
their manifests; ``run_time`` sums each stage's wall-clock time from them into a volatile table.

Every file in the artifact is a function of the version key alone (no wall-clock times, except
the ``VOLATILE_FILES``; no absolute paths; PNGs are written without the "Software" metadata), so
two runs into different roots give byte-identical files (``log.rrd`` aside, see
``pipeline.tracking``).

Command line::

    python -m pipeline.report experiment=smoke
    python -m pipeline.report experiment=smoke report.generate_version=<version> report.force=true
    python -m pipeline.report experiment=smoke report.generate_version=<g> report.label_version=<l>
"""

from pipeline.report.stage import main, report

__all__ = ["main", "report"]
