"""``teleop compare --scenario palpation|retraction|retraction-y --plant mujoco`` (issue 36,
docs/design.md 21.4): every controller through the experiment in one run, the issue's targets met by each, the
QP and mink against the CJM (the other controller as the reference), the table against
the file, and the options a contact scenario would ignore refused by name."""

from __future__ import annotations

import json
import re

import pytest

from teleop.cli.main import main

SPECS = ("cjm", "qp:daqp", "mink:daqp")


@pytest.mark.parametrize("scenario, setpoint", [("palpation", 1.0), ("retraction", 0.5),
                                                 ("retraction-y", 0.5)])
def test_a_contact_scenario_compares_every_controller_and_meets_the_targets(tmp_path, capsys,
                                                                            scenario, setpoint):
    code = main(["compare", "--scenario", scenario, "--plant", "mujoco", "--controllers",
                 ",".join(SPECS), "--out", str(tmp_path), "--quiet"])
    assert code == 0
    document = json.loads((tmp_path / "contact_metrics.json").read_text())
    assert (tmp_path / "contact_force.png").stat().st_size > 0
    assert document["scenario"] == scenario and list(document["controllers"]) == list(SPECS)
    assert document["acceleration_limits"] is True and document["sensor_noise_n"] == 0.0
    assert document["setpoint_n"] == setpoint
    for spec, measures in document["controllers"].items():
        # issue 36's targets: force RMS 10 % of the setpoint (0.1 N around 1 N), no loss
        # of contact, port force 0.2 N, hole error 0.1 mm
        assert measures["force_error_rms"] <= 0.1 * setpoint, spec
        assert measures["contact_lost"] == 0, spec
        assert measures["port_force_max"] <= 0.2, spec
        assert measures["hole_error_max"] <= 1e-4, spec
        # the tissue's force read within the tool's weight (0.98 mN) and a little
        assert measures["sensed_vs_true_max"] <= 0.01, spec
    cjm = document["controllers"]["cjm"]
    for spec in SPECS[1:]:  # no bound is active: each solves the CJM's weighted problem
        other = document["controllers"][spec]
        assert other["force_error_rms"] == pytest.approx(cjm["force_error_rms"], abs=1e-5)
        assert other["hole_error_max"] == pytest.approx(cjm["hole_error_max"], abs=1e-6)
        assert other["ee_error_max"] == pytest.approx(cjm["ee_error_max"], abs=1e-5)
    table = capsys.readouterr().out
    lines = {line.split()[0]: line.split() for line in table.splitlines() if line.strip()}
    for spec in SPECS:
        assert float(lines[spec][1]) == pytest.approx(
            document["controllers"][spec]["force_error_rms"], abs=1e-4)
        assert int(lines[spec][3]) == document["controllers"][spec]["contact_lost"]


@pytest.mark.parametrize("options, message", [
    ([], "needs --plant mujoco: the kinematic plant has no force/torque sensor"),
    (["--plant", "mujoco", "--encoder-noise", "0.001"], "--encoder-noise does not apply"),
    (["--plant", "mujoco", "--trocar-shift", "0.01", "--kp", "10"],
     "--kp, --trocar-shift do not apply"),
    (["--plant", "mujoco", "--force-filter", "600"], "below the Nyquist frequency 500 Hz"),
    (["--plant", "mujoco", "--force-filter", "8"], "force_gain 1.0 .* force filter"),
])
def test_palpation_refuses_what_it_cannot_do_by_name(tmp_path, capsys, options, message):
    code = main(["compare", "--scenario", "palpation", "--controllers", "cjm", "--quiet",
                 "--out", str(tmp_path), "--duration", "0.01", *options])
    assert code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert re.search(message, err), err
    assert not (tmp_path / "contact_metrics.json").exists()


def test_the_scenarios_list_names_palpation(capsys):
    assert main(["scenarios"]) == 0
    listed = capsys.readouterr().out.splitlines()
    for name in ("palpation", "retraction", "retraction-y"):
        assert any(line.startswith(f"{name} ") for line in listed)



@pytest.mark.parametrize("command", [
    ["record", "--scenario", "retraction-y", "--plant", "mujoco", "{out}/run.npz"],
    ["sweep", "--out", "{out}/sweep", "--scenarios", "paper-hole,retraction-y",
     "--controllers", "cjm", "--plants", "mujoco"],
])
def test_record_and_sweep_send_a_contact_scenario_to_compare_by_name(tmp_path, capsys,
                                                                     command):
    """They run plans; a contact scenario's force law reads the plant's sensor every
    period, which only ``teleop compare`` runs."""
    code = main([word.format(out=tmp_path) for word in command])
    assert code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert re.search(f"retraction-y is a contact scenario .*: teleop {command[0]} runs the "
                     f"plan scenarios only; run it with teleop compare --scenario "
                     f"retraction-y --plant mujoco", err), err
    assert not (tmp_path / "run.npz").exists()
    assert not (tmp_path / "sweep" / "results.sqlite").exists()


@pytest.mark.parametrize("options, faults", [
    ([], None),  # the interface checks nothing: not measured
    (["--interface-limits", "count"], 0),  # the controller keeps the limits it checks
    (["--interface-limits", "count", "--no-acceleration-limits"], 1),  # the step from rest
    (["--interface-limits", "strict", "--no-acceleration-limits"], 1),
])
def test_a_contact_run_reports_the_interfaces_faults(tmp_path, capsys, options, faults):
    code = main(["compare", "--scenario", "palpation", "--plant", "mujoco", "--controllers",
                 "cjm", "--duration", "2.6", "--out", str(tmp_path), "--no-plots", *options])
    assert code == 0
    measures = json.loads((tmp_path / "contact_metrics.json").read_text())["controllers"]["cjm"]
    assert measures["interface_faults"] == faults
    row = capsys.readouterr().out.splitlines()[2].split()
    assert row[0] == "cjm" and row[-1] == ("-" if faults is None else str(faults))
    if "strict" in options:  # stopped at the approach's first command: it never touches
        assert measures["contact_lost"] > 0 and measures["force_error_max"] == 1.0


def test_a_contact_run_shorter_than_its_window_is_refused_by_name(tmp_path, capsys):
    code = main(["compare", "--scenario", "palpation", "--plant", "mujoco", "--controllers",
                 "cjm", "--duration", "0.5", "--out", str(tmp_path)])
    assert code == 2
    assert ("palpation: duration 0.5 s ends before its measures' window starts at 2.5 s"
            in capsys.readouterr().err)
