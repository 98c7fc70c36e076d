"""Assessment runs and reports: one TOML config, one command, a self-contained HTML report.

>>> from lidarqa.report import assess                      # doctest: +SKIP
>>> run = assess("assessment.toml", "out")                 # doctest: +SKIP
>>> run.html_path                                          # doctest: +SKIP
PosixPath('out/report.html')

See :mod:`lidarqa.report.config` for the config layout and
:mod:`lidarqa.report.analyses` for the analyses it can run. Plots need
matplotlib (``pip install 'lidarqa[report]'``).
"""

from .config import AssessmentConfig, load_config, parse_config
from .run import AssessmentRun, assess, check_out_dir, demo_config_path, run_assessment

__all__ = [
    "AssessmentConfig",
    "AssessmentRun",
    "assess",
    "check_out_dir",
    "demo_config_path",
    "load_config",
    "parse_config",
    "run_assessment",
]
