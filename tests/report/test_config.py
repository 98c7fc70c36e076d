"""Config validation: everything is refused before any work, with the key's name in the message."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lidarqa.errors import ConfigError, CRSMismatchError
from lidarqa.report import _registry
from lidarqa.report.config import ConfigCRSMismatchError, load_config

from .conftest import LIGHT_TOML, write_config

_registry.specs()  # the built-in analyses registered, so that the tests' patches hold


@pytest.fixture
def light(synthetic, tmp_path) -> str:
    return LIGHT_TOML.format(d=synthetic["dir"].as_posix())


def _cfg(tmp_path: Path, text: str) -> Path:
    return write_config(tmp_path / "c.toml", text)


def test_valid_config_parses(light, tmp_path):
    cfg = load_config(_cfg(tmp_path, light))
    assert [a.id for a in cfg.analyses] == ["lines", "checkpoints"] or sorted(
        a.id for a in cfg.analyses
    ) == ["checkpoints", "lines"]
    cp = next(a for a in cfg.analyses if a.kind == "checkpoints")
    assert cp.targets == {"rmse_z": 0.10}
    assert cfg.inputs["scene"].file_crs is not None  # read from the LAS header


def test_unknown_top_level_key_lists_valid_keys(light, tmp_path):
    with pytest.raises(ConfigError) as e:
        load_config(_cfg(tmp_path, "colour = 'red'\n" + light))
    msg = str(e.value)
    assert "'colour'" in msg and "valid keys" in msg and "inputs" in msg and "heights" in msg


def test_unknown_analysis_key_names_key_and_lists_library_params(light, tmp_path):
    text = light.replace("[lines]\n", "[lines]\nweigth = 5\n")
    with pytest.raises(ConfigError) as e:
        load_config(_cfg(tmp_path, text))
    msg = str(e.value)
    assert "'weigth'" in msg and "[lines]" in msg and "did you mean 'weight'" in msg
    assert (
        "weight" in msg and "sensitivity" in msg
    )  # valid keys come from match_segments' signature


def test_unknown_key_in_nested_table(synthetic, tmp_path):
    d = synthetic["dir"].as_posix()
    text = f"""
[inputs.clouds]
scene = {{ path = "{d}/scene.las", crss = "EPSG:2154" }}
[info]
cloud = "scene"
"""
    with pytest.raises(ConfigError, match="'crss'"):
        load_config(_cfg(tmp_path, text))


def test_missing_input_file(light, tmp_path, synthetic):
    text = light.replace("check.csv", "nope.csv")
    with pytest.raises(ConfigError) as e:
        load_config(_cfg(tmp_path, text))
    assert (
        "'check'" in str(e.value)
        and "nope.csv" in str(e.value)
        and "does not exist" in str(e.value)
    )


def test_relative_paths_resolve_against_the_config_folder(synthetic, tmp_path):
    import shutil

    shutil.copy(synthetic["dir"] / "scene.las", tmp_path / "scene.las")
    cfg = load_config(
        _cfg(tmp_path, '[inputs.clouds]\nscene = "scene.las"\n[info]\ncloud = "scene"\n')
    )
    assert cfg.inputs["scene"].path == tmp_path / "scene.las"


@pytest.mark.parametrize(
    "replace, key",
    [
        ("vertical = true", 'vertical = "yes"'),
        ("target_rmse_z = 0.10", 'target_rmse_z = "small"'),
        ("[lines]\n", '[lines]\nweight = "heavy"\n'),
        ("[lines]\n", "[lines]\nthreshold = [1, 2]\n"),
    ],
)
def test_wrong_type_names_the_key(light, tmp_path, replace, key):
    old = replace if replace in light else replace
    text = light.replace(old, key if old != "[lines]\n" else key)
    name = key.split("=")[0].strip().split("\n")[-1]
    with pytest.raises(ConfigError) as e:
        load_config(_cfg(tmp_path, text))
    assert f"'{name}'" in str(e.value) and "must be" in str(e.value)


def test_undeclared_input_name(light, tmp_path):
    with pytest.raises(ConfigError) as e:
        load_config(_cfg(tmp_path, light.replace('check = "check"', 'check = "cheque"')))
    assert "'cheque'" in str(e.value) and "not declared" in str(e.value)


def test_input_of_the_wrong_kind(light, tmp_path):
    with pytest.raises(ConfigError, match="expected \\[inputs.points\\]"):
        load_config(
            _cfg(
                tmp_path,
                light.replace('check = "check"', 'check = "test"').replace(
                    "[inputs.segments]", "[inputs.segments]"
                ),
            )
        )


def test_invalid_toml(tmp_path):
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(_cfg(tmp_path, "[info\ncloud = 1"))


def test_no_analysis(synthetic, tmp_path):
    d = synthetic["dir"].as_posix()
    with pytest.raises(ConfigError, match="no analysis"):
        load_config(_cfg(tmp_path, f'[inputs.clouds]\nscene = "{d}/scene.las"\n'))


def _write_cloud(path: Path, crs: str | None) -> Path:
    import lidarqa
    from lidarqa.io import PointCloud
    from lidarqa.io.crs import parse_crs

    rng = np.random.default_rng(0)
    xyz = rng.uniform([500000, 5000000, 0], [500050, 5000050, 5], size=(200, 3))
    cloud = PointCloud(
        xyz=xyz,
        fields={"classification": np.full(200, 2, np.uint8)},
        crs=parse_crs(crs) if crs else None,
    )
    lidarqa.write(cloud, path)
    return path


def test_crs_mismatch_between_inputs(tmp_path):
    _write_cloud(tmp_path / "a.las", "EPSG:2154")
    _write_cloud(tmp_path / "b.las", "EPSG:32632")
    text = (
        '[inputs.clouds]\na = "a.las"\nb = "b.las"\n[[info]]\ncloud = "a"\n[[info]]\ncloud = "b"\n'
    )
    with pytest.raises(ConfigCRSMismatchError) as e:
        load_config(_cfg(tmp_path, text))
    assert isinstance(e.value, ConfigError) and isinstance(e.value, CRSMismatchError)
    assert "'a'" in str(e.value) and "'b'" in str(e.value)


def test_crs_mismatch_with_the_configured_crs(tmp_path):
    _write_cloud(tmp_path / "a.las", "EPSG:32632")
    text = 'crs = "EPSG:2154"\n[inputs.clouds]\na = "a.las"\n[info]\ncloud = "a"\n'
    with pytest.raises(ConfigCRSMismatchError, match="'a'.*'crs'"):
        load_config(_cfg(tmp_path, text))


def test_declared_crs_for_a_file_without_one(tmp_path):
    _write_cloud(tmp_path / "a.las", None)
    _write_cloud(tmp_path / "b.las", "EPSG:2154")
    text = (
        '[inputs.clouds]\na = { path = "a.las", crs = "EPSG:32632" }\nb = "b.las"\n'
        '[[info]]\ncloud = "a"\n[[info]]\ncloud = "b"\n'
    )
    with pytest.raises(ConfigCRSMismatchError):
        load_config(_cfg(tmp_path, text))
    ok = text.replace("EPSG:32632", "EPSG:2154")
    cfg = load_config(_cfg(tmp_path, ok))
    assert [a.id for a in cfg.analyses] == ["info-1", "info-2"]


def test_cli_refuses_bad_config_before_any_work(light, tmp_path, monkeypatch):
    """Exit 1, one line naming the key, and no output folder created, no analysis called."""
    from click.testing import CliRunner

    from lidarqa.cli.main import cli

    called = []
    monkeypatch.setitem(_registry.ANALYSES, "lines", lambda *a: called.append(1))
    cfg = _cfg(tmp_path, light.replace("[lines]\n", "[lines]\nbogus_option = 1\n"))
    out = tmp_path / "out"
    r = CliRunner().invoke(cli, ["assess", str(cfg), "--out", str(out), "-q"])
    assert r.exit_code == 1
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "'bogus_option'" in lines[0] and lines[0].startswith("Error:")
    assert "Traceback" not in r.output
    assert not out.exists() and called == []


def test_demo_config_is_a_normal_config():
    from lidarqa.report.run import demo_config_path

    cfg = load_config(demo_config_path(), skip_unavailable=True)
    kinds = {a.kind for a in cfg.analyses} | {k for k, _, _ in cfg.skipped}
    assert kinds == {"info", "ground", "edges", "lines", "checkpoints", "heights", "swaths"}
    assert all("not available" in r or "lacks" in r for _, _, r in cfg.skipped)
    heights = next((a for a in cfg.analyses if a.kind == "heights"), None)
    if heights is not None:
        assert heights.options["reference"] == {
            "from_cloud": True,
            "fraction": 0.5,
            "seed": 0,
            "max_points": 5000,
        }
        assert heights.params["sigma_ref"] == 0.04


def test_unavailable_analysis_is_refused_unless_skipping(synthetic, tmp_path, monkeypatch):
    from lidarqa.report.config import AnalysisUnavailableError

    def unavailable(options):
        raise AnalysisUnavailableError(
            "analysis [lines] needs lidarqa.accuracy.lines, which is missing"
        )

    monkeypatch.setitem(_registry._PARAMS, "lines", unavailable)
    text = LIGHT_TOML.format(d=synthetic["dir"].as_posix())
    with pytest.raises(AnalysisUnavailableError, match="lidarqa.accuracy.lines"):
        load_config(_cfg(tmp_path, text))
    cfg = load_config(_cfg(tmp_path, text), skip_unavailable=True)
    assert [a.kind for a in cfg.analyses] == ["checkpoints"]
    assert cfg.skipped[0][0] == "lines"


def test_out_of_range_filter_parameter_is_refused_before_work(synthetic, tmp_path):
    d = synthetic["dir"].as_posix()
    text = (f'[inputs.clouds]\nscene = "{d}/scene.las"\n'
            '[ground]\ncloud = "scene"\niter_angle = 120.0\n')
    with pytest.raises(ConfigError, match=r"\[ground\].*iter_angle"):
        load_config(_cfg(tmp_path, text))
