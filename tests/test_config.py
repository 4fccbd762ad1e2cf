"""Job-file loader: defaults, path resolution, unknown keys and wrong types name the key."""

import pytest

from insgnss.config import load_job, load_job_dict, schema_markdown
from insgnss.errors import ConfigError


def test_defaults_and_resolution(tmp_path):
    job_file = tmp_path / "sub" / "job.toml"
    job_file.parent.mkdir()
    job_file.write_text('[job]\nname = "x"\n[inputs.imu]\npath = "data/imu.csv"\n'
                        '[filter]\nsmoother = false\npropagation_interval = 1\n')
    job = load_job(job_file)
    assert job["job"]["name"] == "x"
    assert job["filter"]["smoother"] is False
    assert job["filter"]["propagation_interval"] == 1.0
    assert isinstance(job["filter"]["propagation_interval"], float)
    assert job["aiding"]["gnss_position"] is True
    assert job.resolve(job["inputs"]["imu"]["path"]) == (tmp_path / "sub" / "data" / "imu.csv")
    assert job.output_dir == tmp_path / "sub" / "out"
    assert tmp_path / "sub" / "data" / "imu.csv" in job.input_paths()


@pytest.mark.parametrize("text,key", [
    ("[filter]\nsmoothr = true\n", "filter.smoothr"),
    ("[inputs.imu]\ngyro_units = 'deg/s'\n", "inputs.imu.gyro_units"),
    ("[bogus]\nx = 1\n", "bogus"),
    ("[outages.periodic]\nstart = 40\nlenght = 15\n", "outages.periodic.lenght"),
])
def test_unknown_keys_are_named(tmp_path, text, key):
    f = tmp_path / "job.toml"
    f.write_text(text)
    with pytest.raises(ConfigError) as exc:
        load_job(f)
    assert exc.value.column == key and "unknown key" in str(exc.value)
    assert str(f) in str(exc.value)


@pytest.mark.parametrize("data,key", [
    ({"filter": {"smoother": "yes"}}, "filter.smoother"),
    ({"filter": {"propagation_interval": True}}, "filter.propagation_interval"),
    ({"filter": {"process_model": "ekf9"}}, "filter.process_model"),
    ({"inputs": {"imu": "file.csv"}}, "inputs.imu"),
    ({"aiding": {"nhc_std": 0.1}}, "aiding.nhc_std"),
])
def test_wrong_types_are_named(data, key):
    with pytest.raises(ConfigError) as exc:
        load_job_dict(data, "job.toml")
    assert exc.value.column == key


def test_bad_toml_reports_line(tmp_path):
    f = tmp_path / "job.toml"
    f.write_text("[job]\nname = 'a'\nthis is not toml\n")
    with pytest.raises(ConfigError) as exc:
        load_job(f)
    assert exc.value.row == 3


def test_simulation_tables_pass_through():
    job = load_job_dict({"scenario": {"seed": 3}, "filter": {"smoother": True}})
    assert job.simulation == {"scenario": {"seed": 3}}


def test_schema_markdown_lists_every_table():
    md = schema_markdown()
    for t in ("[inputs.imu]", "[aiding]", "[outages.periodic]", "[filter]", "[outputs]"):
        assert t in md


def test_simulation_tables_match_simulator():
    from insgnss.config import SIMULATION_TABLES
    from insgnss.simulate.scenario import SIM_TABLES

    assert set(SIM_TABLES) <= set(SIMULATION_TABLES)


def test_docs_jobs_md_lists_every_key():
    from pathlib import Path

    from insgnss.config import schema_markdown

    doc = (Path(__file__).resolve().parents[1] / "docs" / "jobs.md").read_text()
    for line in schema_markdown().splitlines():
        if line.startswith("| `"):
            key = line.split("`")[1]
            assert f"`{key}`" in doc, f"docs/jobs.md lacks {key}"


def test_docs_jobs_md_examples_are_valid_jobs():
    import re
    import tomllib
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[1] / "docs" / "jobs.md").read_text()
    blocks = re.findall(r"```toml\n(.*?)```", doc, flags=re.S)
    assert len(blocks) >= 5
    for b in blocks:
        load_job_dict(tomllib.loads(b), "docs/jobs.md")


def test_docs_jobs_md_schema_section_is_generated_from_the_schema():
    """docs/jobs.md "Schema" ends with exactly schema_markdown() (regenerate it with
    ``python -c "from insgnss.config import schema_markdown; print(schema_markdown())"``)."""
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[1] / "docs" / "jobs.md").read_text()
    assert doc.endswith(schema_markdown())


def test_docs_jobs_md_states_the_robustness_rules():
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[1] / "docs" / "jobs.md").read_text()
    section = doc[doc.index("## Robustness and bad input"):doc.index("## Examples")]
    for rule in ("finite", "a key the run would not read is an error", "at least one IMU interval",
                 "check_output_location", "in use by pid", "--wait", "stale",
                 "never deletes, moves or changes one of its inputs", "hard links",
                 "overlap in time",
                 "job.time_base", "Removed keys"):
        assert rule in section, rule
