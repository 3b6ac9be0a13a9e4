"""The console commands' package (measure.commands): how each command line parses, what the
commands share (exit status 2, atomic writes, progress, cache folders), `jsss` and `jsss info`.

Parsing is checked in this process (the parsers import nothing heavy); the console scripts
themselves run as subprocesses in test_cli.py (fit-params), tests/jsss/render/test_scene.py
(jsss-render) and tests/fitting/test_render.py (jsss-render fit)."""

import argparse
import csv
import os
import stat
import subprocess
import sys

import pytest

from measure.commands import _console, fit_params, info, render


# ----------------------------------------------------------------------------- parsing
def test_fit_params_command_lines_of_the_readme_parse_to_their_command():
    """Every fit-params line of the README parses to the single fit or to batch, with its values."""
    parse = fit_params.parser().parse_args
    demo = parse(["--demo"])
    assert demo.run is fit_params._fit and demo.demo and demo.measurement == []
    single = parse("sample.exr --reference sample_ref.exr --pixel-mm 0.05 --eta 1.3 --json".split())
    assert single.run is fit_params._fit and single.measurement == ["sample.exr"]
    assert (single.reference, single.pixel_mm, single.eta, single.json) == ("sample_ref.exr", 0.05, 1.3, True)
    brackets = parse("t0.exr t1.exr t2.exr --saturation 0.2 --reference ref.exr --eta 1.3".split())
    assert brackets.measurement == ["t0.exr", "t1.exr", "t2.exr"] and brackets.saturation == 0.2
    batch = parse("batch measurements/ --out table.csv --eta 1.3 --workers 2 --resume".split())
    assert batch.run is fit_params._batch and batch.command == "batch"
    assert (batch.target, batch.out, batch.eta, batch.workers, batch.resume) == ("measurements/", "table.csv", 1.3,
                                                                                  2, True)


def test_options_may_come_before_the_file_and_a_subcommand():
    """argparse, not argv[0], tells a file from a subcommand: options before the file are kept
    (repeatable ones add up across it), options before `batch` do not make it a file, and a
    file named like the subcommand is given as ./batch."""
    parse = fit_params.parser().parse_args
    args = parse("--json --eta 1.5 --export pbrt sample.exr --reference r.exr --export mitsuba".split())
    assert args.run is fit_params._fit and args.measurement == ["sample.exr"]
    assert args.json and args.eta == 1.5 and args.reference == "r.exr" and args.export == ["pbrt", "mitsuba"]
    assert parse("-q batch measurements/ --out t.csv".split()).run is fit_params._batch
    named = parse("./batch --reference r.exr".split())
    assert named.run is fit_params._fit and named.measurement == ["./batch"]


def test_jsss_render_and_jsss_command_lines_parse_to_their_command():
    parse = render.parser().parse_args
    one = parse("examples/marble_sphere.toml -o marble.png --plan --timings".split())
    assert one.run is render._render and one.scenes == ["examples/marble_sphere.toml"]
    assert one.output == "marble.png" and one.plan and one.timings and one.prog == "jsss-render"
    several = parse("examples/a.toml examples/b.toml -o renders/ --method lambert".split())
    assert several.scenes == ["examples/a.toml", "examples/b.toml"] and several.method == "lambert"
    fit = parse("fit scene.toml photo.exr --json --profile transport --mask mask.png --saturation 60000".split())
    assert fit.run is render._fit and fit.prog == "jsss-render fit"
    assert (fit.scene, fit.photo, fit.profile, fit.mask, fit.saturation) == ("scene.toml", "photo.exr", "transport",
                                                                              "mask.png", 60000.0)
    assert info.parser().parse_args([]).run is info._table
    assert info.parser().parse_args(["table"]).run is info._table
    assert info.parser().parse_args(["info"]).run is info._info


@pytest.mark.parametrize("make, argv", [
    (fit_params.parser, ["sample.exr", "--no-such-option"]),
    (fit_params.parser, ["batch", "dir"]),  # --out is required
    (render.parser, []),  # a scene or `fit`
    (render.parser, ["fit", "scene.toml"]),  # and the photo
    (render.parser, ["scene.toml", "--method", "raytrace"]),
    (fit_params.parser, ["sample.exr", "--export", "maya"]),
    (info.parser, ["tabel"]),
])
def test_a_malformed_command_line_is_a_usage_error_with_status_2(make, argv, capsys):
    """One line naming the flag and pointing at --help (argparse printed its usage block first)."""
    with pytest.raises(SystemExit) as exit_:
        make().parse_args(argv)
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and err.count("\n") == 1 and "error:" in err and "--help)" in err, err


def _parsers(parser, name):
    """(name, parser) of a command and of each of its subcommands."""
    yield name, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub, subparser in action._name_parser_map.items():
                yield f"{name} {sub}", subparser


@pytest.mark.parametrize("name, parser", [
    *_parsers(fit_params.parser(), "fit-params"), *_parsers(render.parser(), "jsss-render"),
    *_parsers(info.parser(), "jsss")])
def test_help_lists_every_option_with_its_explanation(name, parser):
    """--help of each command and subcommand names every option it accepts, each with a help text."""
    text = parser.format_help()
    for action in parser._actions:
        for flag in action.option_strings:
            assert flag in text, (name, flag)
        assert action.help, (name, action.dest)


@pytest.mark.parametrize("module, extra", [
    ("measure.commands.render", []), ("measure.commands.render", ["fit"]), ("measure.commands.fit_params", []),
    ("measure.commands.fit_params", ["batch"]), ("measure.commands.fit_params", ["pixel-size"]),
    ("measure.commands.info", [])])
def test_every_command_has_a_version_and_plain_help(module, extra):
    """--version on each command and subcommand; help text without reST markup (before:
    ``jsss-render``: in the description), and every option explained."""
    import jsss

    out = subprocess.run([sys.executable, "-m", module, *extra, "--version"], capture_output=True, text=True,
                         stdin=subprocess.DEVNULL, timeout=120)
    assert out.returncode == 0 and jsss.__version__ in out.stdout, out.stderr
    help_text = subprocess.run([sys.executable, "-m", module, *extra, "--help"], capture_output=True, text=True,
                               stdin=subprocess.DEVNULL, timeout=120).stdout
    assert "``" not in help_text and ":math:" not in help_text
    lines = help_text.splitlines() + [""]
    # An option's help follows its name after two spaces, or on the next, indented line.
    bare = [line for line, after in zip(lines, lines[1:]) if line.startswith("  -")
            and "  " not in line.strip() and not after.startswith(" " * 10)]
    assert not bare and "--version" in help_text


# ----------------------------------------------------------------------------- exit status
def test_bad_input_is_one_line_and_status_2_and_a_bug_is_not_hidden(capsys):
    """A UsageError or the library's ValueError/OSError: status 2 and the message's first line,
    prefixed with the command; an interrupt: 130; anything else (a bug) keeps its traceback."""

    def fail(error):
        raise error

    assert _console.exit_status("cmd", lambda: 0) == 0
    assert _console.exit_status("cmd", fail, _console.UsageError("--eta must be > 0\nmore advice")) == 2
    assert capsys.readouterr().err == "cmd: error: --eta must be > 0\n"
    assert _console.exit_status("cmd", fail, FileNotFoundError(2, "No such file", "x.exr")) == 2
    assert capsys.readouterr().err == "cmd: error: [Errno 2] No such file: 'x.exr'\n"
    assert _console.exit_status("cmd", fail, ValueError()) == 2
    assert capsys.readouterr().err == "cmd: error: ValueError\n"
    assert _console.exit_status("cmd", fail, KeyboardInterrupt()) == 130
    with pytest.raises(ZeroDivisionError):
        _console.exit_status("cmd", lambda: 1 / 0)


def test_a_command_with_bad_input_exits_2_with_one_line(capsys, tmp_path):
    """Through main(): a missing measurement is one line naming the file, status 2."""
    assert fit_params.main([str(tmp_path / "nope.exr"), "--reference", str(tmp_path / "ref.exr")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("fit-params: error: ") and "nope.exr: no such file" in err


# ----------------------------------------------------------------------------- atomic writes
def test_atomic_write_replaces_the_file_whole_and_leaves_no_temporary_file(tmp_path):
    """The new content replaces the old in one step, in a folder made for it, with the
    permissions a plain open gives (mkstemp's are 0600); a writer that fails leaves the old
    file as it was and no temporary file."""
    out = tmp_path / "new" / "table.csv"
    assert _console.write_text(out, "a,b\n1,2\n") == out
    assert out.read_text() == "a,b\n1,2\n"
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(out.stat().st_mode) == 0o666 & ~umask

    def broken(tmp):
        with open(tmp, "w") as handle:
            handle.write("half a ta")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        _console.write_atomically(out, broken)
    assert out.read_text() == "a,b\n1,2\n"
    assert [p.name for p in out.parent.iterdir()] == ["table.csv"]


def test_a_batch_writes_rows_as_they_finish_and_resumes_after_an_interrupt(monkeypatch, tmp_path, capsys):
    """Interrupted at its third image, a batch exits 130 with the two finished rows in its table
    (written atomically: no temporary file); --resume fits only the rest, and the table is then
    whole and in the files' order."""
    for name in ("a", "b", "c", "d"):
        (tmp_path / f"{name}.exr").write_bytes(b"")
    fitted = []

    def fake_row(job, options):
        if job[0].name == "c.exr" and not fitted[2:]:
            raise KeyboardInterrupt
        fitted.append(job[0].name)
        return {"file": str(job[0]), "status": "ok", "error": "", "sigma_a_R": len(fitted)}

    monkeypatch.setattr(fit_params, "_fit_row", fake_row)
    out = tmp_path / "table.csv"
    assert fit_params.main(["batch", str(tmp_path), "--out", str(out), "-q"]) == 130
    assert [row["file"][-5:] for row in csv.DictReader(out.open())] == ["a.exr", "b.exr"]
    fitted.append("(interrupted)")
    assert fit_params.main(["batch", str(tmp_path), "--out", str(out), "--resume", "-q"]) == 0
    assert fitted[3:] == ["c.exr", "d.exr"]  # a and b were not fitted again
    rows = list(csv.DictReader(out.open()))
    assert [row["file"][-5:] for row in rows] == ["a.exr", "b.exr", "c.exr", "d.exr"]
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix != ".exr") == ["table.csv"]
    assert "resuming: 2 row(s)" in capsys.readouterr().err


# ----------------------------------------------------------------------------- progress
def test_progress_lines_go_to_stderr_only_where_asked(capsys):
    """Off by default where stderr is not a terminal (as under pytest), off with -q, and on
    where asked: one line on stderr with the command and the seconds, nothing on stdout."""
    _console.Progress("cmd")("quiet")
    _console.Progress("cmd", enabled=False)("quiet")
    _console.Progress("cmd", enabled=True)("reading")
    out, err = capsys.readouterr()
    assert out == "" and err.startswith("cmd: [") and err.endswith(" s] reading\n") and "quiet" not in err
    with _console.Progress("cmd", enabled=True).bar(3, desc="batch") as bar:
        bar.update(3)
    assert "3/3" in capsys.readouterr().err


# ----------------------------------------------------------------------------- caches
def test_cache_folders_follow_the_environment(monkeypatch, tmp_path):
    monkeypatch.delenv("JAX_COMPILATION_CACHE_DIR", raising=False)
    monkeypatch.delenv("JSSS_COMPILATION_CACHE", raising=False)
    monkeypatch.setenv("JSSS_CACHE_DIR", str(tmp_path / "jsss"))
    assert _console.cache_dir() == tmp_path / "jsss"
    assert _console.compilation_cache_dir() == tmp_path / "jsss" / "xla"
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(tmp_path / "jax"))  # JAX's own variable wins
    assert _console.compilation_cache_dir() == tmp_path / "jax"
    monkeypatch.setenv("JSSS_COMPILATION_CACHE", "0")
    assert _console.compilation_cache_dir() is None
    monkeypatch.delenv("JSSS_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert _console.cache_dir() == tmp_path / "xdg" / "jsss"


CACHE_SCRIPT = """
import os, sys, warnings, jax
from fitting import programs
from measure.commands._console import enable_caches
where = enable_caches()
print(where, jax.config.jax_compilation_cache_dir, programs.stored_programs.folder())
os.environ["JAX_COMPILATION_CACHE_DIR"] = sys.argv[1] + "/jax"
print(enable_caches())
os.environ["JSSS_COMPILATION_CACHE"] = "0"
print(enable_caches())
del os.environ["JSSS_COMPILATION_CACHE"]
os.environ["JAX_COMPILATION_CACHE_DIR"] = sys.argv[1] + "/a_file/xla"
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    print(enable_caches(), len(caught), str(caught[0].message).split(":")[0] if caught else "")
"""


def test_enable_caches_turns_on_jax_and_the_program_store_and_an_unwritable_folder_warns(tmp_path):
    """Run in a subprocess: it changes JAX's configuration, which this process keeps as it is."""
    (tmp_path / "a_file").write_text("not a directory")
    env = {"PATH": "", "HOME": str(tmp_path), "JSSS_CACHE_DIR": str(tmp_path / "jsss")}
    out = subprocess.run([sys.executable, "-c", CACHE_SCRIPT, str(tmp_path)], capture_output=True, text=True, env=env,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    xla = f"{tmp_path}/jsss/xla"
    assert lines[0] == f"{xla} {xla} {xla}"  # JSSS_CACHE_DIR/xla, JAX uses it, and so do the traced programs
    assert lines[1] == f"{tmp_path}/jax"  # JAX's own variable wins
    assert lines[2] == "None"  # JSSS_COMPILATION_CACHE=0 turns it off
    assert lines[3] == f"None 1 {tmp_path}/a_file/xla"  # unwritable: one warning naming it, no cache
    assert (tmp_path / "jsss" / "xla").is_dir()


FILL_SCRIPT = """
import sys, jax, jax.numpy as jnp
if sys.argv[2] == "jax":  # JAX's own cache, as a user's scripts or an older jsss filled it
    jax.config.update("jax_compilation_cache_dir", sys.argv[1])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
else:
    from measure.commands._console import start
    start()
print(float(jax.jit(lambda x: jnp.sin(x) * float(sys.argv[3]))(jnp.ones(3))[0]))
"""


def test_a_cache_folder_filled_by_plain_jax_takes_the_commands_programs(tmp_path):
    """A folder of entries without JAX's eviction records ("-atime" files, written only under a
    size limit) keeps working: with a limit, every write there failed with a warning."""
    env = {"PATH": "", "HOME": str(tmp_path), "JSSS_CACHE_DIR": str(tmp_path / "jsss")}
    folder = tmp_path / "jsss" / "xla"
    for who, factor in (("jax", "2.0"), ("jsss", "3.0")):
        out = subprocess.run([sys.executable, "-c", FILL_SCRIPT, str(folder), who, factor], capture_output=True,
                             text=True, env=env, timeout=120)
        assert out.returncode == 0, out.stderr
        assert "persistent compilation cache" not in out.stderr, out.stderr
    entries = sorted(path.name for path in folder.glob("jit__lambda-*-cache"))
    assert len(entries) == 2, entries  # both programs were written, the command's beside JAX's


# ----------------------------------------------------------------------------- jsss, jsss info
def test_jsss_prints_every_material(capsys):
    """`jsss` prints one line per material with both columns."""
    from jsss.materials import jensen2001_names

    assert info.main([]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in jensen2001_names())
    assert "0.1264" in out  # Chicken1 blue, the one channel off by more than 0.01


def test_info_reports_versions_caches_precision_and_devices(monkeypatch, tmp_path):
    """`jsss info` names what a bug report needs, with the cache directories the environment sets."""
    import jax

    monkeypatch.setenv("JSSS_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setenv("JAX_COMPILATION_CACHE_DIR", str(tmp_path / "xla"))
    lines = dict(line.split(": ", 1) for line in info.info_lines())
    assert lines["jax"] == jax.__version__
    for key in ("jsss", "numpy", "OpenEXR", "devices"):
        assert lines[key] and lines[key] != "not installed"
    assert lines["float64 (jax_enable_x64)"].startswith("on")  # the test suite enables it
    assert lines["jsss cache (JSSS_CACHE_DIR)"] == str(tmp_path / "cache")
    assert lines["compilation cache of the commands (JAX_COMPILATION_CACHE_DIR)"] == str(tmp_path / "xla")
    monkeypatch.delenv("JAX_COMPILATION_CACHE_DIR")
    lines = dict(line.split(": ", 1) for line in info.info_lines())
    assert lines["compilation cache of the commands (JAX_COMPILATION_CACHE_DIR)"] == str(tmp_path / "cache" / "xla")
    assert "cpu" in lines["devices"]


def test_jsss_imports_neither_fitting_nor_measure():
    """The physics and the renderer stand alone: no module of jsss names fitting or measure."""
    from pathlib import Path

    import jsss

    root = Path(jsss.__file__).parent
    offenders = [str(p.relative_to(root)) for p in root.rglob("*.py")
                 if any(f"{word} {package}" in p.read_text() for word in ("import", "from")
                        for package in ("fitting", "measure"))]
    assert offenders == []


# ----------------------------------------------------------------------------- scene files
def test_a_fitted_material_replaces_the_scenes_and_keeps_the_users_comments(tmp_path):
    """jsss-render fit's .fit.toml: [material] and its sub-tables (wherever they stand) give way
    to the fit; every other table, key and comment stays as the user wrote it; the file loads."""
    from jsss import Medium
    from jsss.render import load_scene

    from measure.commands._scene_files import fitted_material, scene_with_material, sphere_scene

    text = ('# my marble bust\n[geometry]   # the shape\nshape = "sphere"\nradius = 15.0  # mm\n'
            'segments = 16\nrings = 8\n\n[material]\nname = "marble"  # a guess\nroughness = 0.3\n\n'
            '[[lights]]\ntype = "directional"  # the window\ndirection = [0.5, 1, -0.5]\n\n'
            '[material.gaussians]\nvariances = [1.0]\nweights = [[1, 1, 1]]\n\n'
            '[camera]\nposition = [0, -90, 20]\nresolution = [16, 12]\n')
    medium = Medium([0.01, 0.02, 0.03], [1.0, 1.1, 1.2], 1.4)
    material = fitted_material(medium, profile="transport", g=0.5, roughness=0.3, specular=0.5, comment="fitted")
    (tmp_path / "fit.toml").write_text(scene_with_material(text, material))
    written = (tmp_path / "fit.toml").read_text()
    for kept in ("# my marble bust", "[geometry]   # the shape", "radius = 15.0  # mm", '"directional"  # the window'):
        assert kept in written
    assert "name = " not in written and "gaussians" not in written and "# fitted" in written
    scene = load_scene(tmp_path / "fit.toml")
    assert scene.material.profile_model == "transport" and scene.material.g == 0.5
    assert list(scene.material.medium.sigma_a) == [0.01, 0.02, 0.03]  # to the last bit
    (tmp_path / "new.toml").write_text(sphere_scene(material, label="fit-params test"))
    assert load_scene(tmp_path / "new.toml").material.medium.eta.tolist() == [1.4, 1.4, 1.4]
    with pytest.raises(ValueError, match="profile must be 'dipole' or 'transport'"):
        fitted_material(medium, profile="pbd", g=0.0)


# ----------------------------------------------------------------------------- batches lose nothing (issue 38)
def _fake_batch(monkeypatch, folder, names=("a", "b", "c", "d")):
    """Measurement files and a fake fit that records what it fitted (and at which eta)."""
    for name in names:
        (folder / f"{name}.exr").write_bytes(b"")
    fitted = []

    def fake_row(job, options):
        fitted.append((job[0].name, options["eta"]))
        return {"file": str(job[0]), "status": "ok", "error": "", "sigma_a_R": 0.01}

    monkeypatch.setattr(fit_params, "_fit_row", fake_row)
    return fitted


def test_a_batch_killed_outright_loses_no_finished_row(monkeypatch, tmp_path, capsys):
    """kill -9 runs no cleanup: every row finished before it is in OUT.journal, on disk, and
    --resume takes it (no row had been written, and 13 finished fits were lost)."""
    fitted = _fake_batch(monkeypatch, tmp_path)
    out = tmp_path / "table.csv"
    real_write = fit_params._write_table

    def killed(rows, path):  # the process dies before any table is written
        raise SystemError("killed")

    monkeypatch.setattr(fit_params, "_write_table", killed)
    with pytest.raises(SystemError):
        fit_params.main(["batch", str(tmp_path), "--out", str(out), "-q"])
    assert not out.exists() and len(fitted) == 4
    monkeypatch.setattr(fit_params, "_write_table", real_write)
    assert fit_params.main(["batch", str(tmp_path), "--out", str(out), "--resume", "-q"]) == 0
    assert len(fitted) == 4  # nothing fitted again
    assert [row["file"][-5:] for row in csv.DictReader(out.open())] == ["a.exr", "b.exr", "c.exr", "d.exr"]
    assert not (tmp_path / "table.csv.journal").exists() and not (tmp_path / "table.csv.lock").exists()
    assert "resuming: 4 row(s)" in capsys.readouterr().err


def test_resume_refits_rows_fitted_with_other_settings(monkeypatch, tmp_path, capsys):
    fitted = _fake_batch(monkeypatch, tmp_path, names=("a", "b"))
    out = tmp_path / "table.csv"
    assert fit_params.main(["batch", str(tmp_path), "--out", str(out), "--eta", "1.5", "-q"]) == 0
    assert fit_params.main(["batch", str(tmp_path), "--out", str(out), "--eta", "1.3", "--resume", "-q"]) == 0
    assert fitted == [("a.exr", 1.5), ("b.exr", 1.5), ("a.exr", 1.3), ("b.exr", 1.3)]
    rows = list(csv.DictReader(out.open()))
    assert len(rows) == 2 and all("eta=1.3" in row["settings"] for row in rows)
    assert "2 fitted with other settings: fitted again" in capsys.readouterr().err
    assert fit_params.main(["batch", str(tmp_path), "--out", str(out), "--eta", "1.3", "--resume", "-q"]) == 0
    assert len(fitted) == 4  # the same settings: kept


def test_two_batches_cannot_write_one_table(monkeypatch, tmp_path, capsys):
    fitted = _fake_batch(monkeypatch, tmp_path, names=("a",))
    out = tmp_path / "table.csv"
    with fit_params._locked(out):  # another batch is running
        assert fit_params.main(["batch", str(tmp_path), "--out", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--out {out}: another fit-params batch is writing this table" in err
    assert fitted == [] and not out.exists()


@pytest.mark.parametrize("where, message", [
    ("folder", "is a directory"), ("table.txt", "the table is .csv"), ("missing/table.csv", "no such folder"),
])
def test_a_bad_out_is_refused_before_any_fit(monkeypatch, tmp_path, capsys, where, message):
    fitted = _fake_batch(monkeypatch, tmp_path, names=("a",))
    (tmp_path / "folder").mkdir()
    assert fit_params.main(["batch", str(tmp_path), "--out", str(tmp_path / where), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and fitted == []


@pytest.mark.parametrize("flags, message", [
    (["--eta", "nan"], "--eta must be > 0"), (["--pixel-mm", "-1"], "--pixel-mm must be > 0"),
    (["--reference-reflectance", "2"], "--reference-reflectance must be in (0, 1]"),
])
def test_a_bad_batch_flag_is_one_line_before_any_fit(monkeypatch, tmp_path, capsys, flags, message):
    """A flag out of range is the whole batch's error (exit 2, nothing fitted), not one failed
    row per image with exit 1."""
    fitted = _fake_batch(monkeypatch, tmp_path, names=("a", "b"))
    assert fit_params.main(["batch", str(tmp_path), "--out", str(tmp_path / "t.csv"), "-q", *flags]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and fitted == []


@pytest.mark.parametrize("content, message", [
    (b"measurement,reference\n\x80\x81,b.exr\n", "is not UTF-8"),
    (b"measurement,reference,eta\na.exr,b.exr,high\n", "line 2: eta 'high' is not a number"),
    (b"measurement,reference\na.exr,\n", "line 2: needs a measurement and a reference"),
])
def test_a_bad_manifest_is_named_with_its_line(monkeypatch, tmp_path, capsys, content, message):
    fitted = _fake_batch(monkeypatch, tmp_path, names=("a",))
    manifest = tmp_path / "m.csv"
    manifest.write_bytes(content)
    assert fit_params.main(["batch", "--manifest", str(manifest), "--out", str(tmp_path / "t.csv"), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(manifest) in err and message in err and fitted == []


def test_resuming_a_table_that_is_not_a_batch_table_names_it(monkeypatch, tmp_path, capsys):
    fitted = _fake_batch(monkeypatch, tmp_path, names=("a",))
    out = tmp_path / "table.csv"
    out.write_text("name,value\nx,1\n")
    assert fit_params.main(["batch", str(tmp_path), "--out", str(out), "--resume", "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no 'file' column" in err and str(out) in err and fitted == []


def test_a_library_warning_is_one_line_naming_the_command(capsys):
    import warnings

    from measure.commands._console import exit_status

    def command():
        warnings.warn("something to know\nand a second line", UserWarning)
        return 0

    assert exit_status("jsss-render", command) == 0
    err = capsys.readouterr().err
    assert err == "jsss-render: warning: something to know\n"


def test_shipped_examples_render_from_any_folder_by_name(tmp_path):
    """example:NAME names a scene that ships with jsss (jsss.examples); example:list lists them;
    an unknown name is one line, exit 2, listing the names."""
    listing = subprocess.run([sys.executable, "-m", "measure.commands.render", "example:list"], capture_output=True,
                             text=True, stdin=subprocess.DEVNULL, timeout=120, cwd=tmp_path)
    assert listing.returncode == 0 and "example:head " in listing.stdout and "example:marble_sphere" in listing.stdout
    bad = subprocess.run([sys.executable, "-m", "measure.commands.render", "example:nope"], capture_output=True,
                         text=True, stdin=subprocess.DEVNULL, timeout=120, cwd=tmp_path)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "example:marble_sphere" in bad.stderr


def test_a_process_past_its_memory_map_budget_lets_its_compiled_programs_go():
    """Each XLA executable a process keeps holds memory maps, of which Linux gives a process
    65530 (past them XLA segfaults): under the budget nothing is let go; past it JAX's compiled
    programs are (the next call compiles again), and a batch row checks after every image."""
    import jax
    import jax.numpy as jnp

    if _console.memory_maps() is None:
        pytest.skip("no /proc/self/maps here")
    assert _console.memory_maps() > 0
    double = jax.jit(lambda x: 2 * x)
    double(jnp.ones(3))
    assert double._cache_size() == 1
    assert not _console.release_compiled_programs(budget=10**9) and double._cache_size() == 1
    assert _console.release_compiled_programs(budget=0) and double._cache_size() == 0


def test_every_batch_row_ends_by_checking_the_memory_map_budget(monkeypatch, tmp_path):
    """A batch's images of many sizes compile many programs: each row, fitted or failed, ends by
    releasing them past the budget (in this process or on a Dask worker, both run _fit_row)."""
    calls = []
    monkeypatch.setattr(fit_params, "release_compiled_programs", lambda: calls.append(1))
    options = {"pixel_mm": None, "eta": 1.3, "reference_reflectance": 0.99, "model": "transport", "g": 0.0,
               "view_angle_deg": 0.0, "white_balance": "none"}
    row = fit_params._fit_row((tmp_path / "missing.exr", tmp_path / "missing_ref.exr", None, {}), options)
    assert row["status"] == "failed" and "missing" in row["error"] and calls == [1]
