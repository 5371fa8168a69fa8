"""The one table reader: valid dialects give identical numbers; bad rows name file:line."""

from __future__ import annotations

import numpy as np
import pytest

from align.calibration.static import STATIC
from axisbase import Column, InputError, TableSpec, iter_table, parse_column_map, read_table
from axisbase.table import rate_warning
from tests.conftest import real_folder

SPEC = TableSpec("test table", (
    Column("pose", "label", required=False, aliases=("label",)),
    Column("ux", aliases=("ax",)), Column("uy", aliases=("ay",)), Column("uz", aliases=("az",)),
    Column("n", "int", required=False),
    Column("t", required=False, aliases=("time",))), time="t")


def _rows(seed: int, n: int = 50):
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3)) * 10 ** rng.uniform(-6, 3)
    t = np.cumsum(rng.uniform(0.001, 0.1, n))
    return [f"p{i // 10}" for i in range(n)], u, t, np.arange(n) + 7


def _write(path, header, rows, *, bom=False, crlf=False, sep=",", order=None):
    order = order or list(range(len(header)))
    nl = "\r\n" if crlf else "\n"
    lines = [sep.join(header[j] for j in order)]
    lines += [sep.join(r[j] for j in order) for r in rows]
    data = nl.join(lines) + nl
    path.write_bytes((b"\xef\xbb\xbf" if bom else b"") + data.encode())
    return path


def _plain(seed):
    labels, u, t, n = _rows(seed)
    rows = [[labels[i], *(repr(float(v)) for v in u[i]), str(n[i]), repr(float(t[i]))]
            for i in range(len(t))]
    return ["pose", "ux", "uy", "uz", "n", "t"], rows


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("variant", ["bom", "crlf", "bom+crlf", "caps", "spaces", "semicolon",
                                     "tab", "reordered", "aliases", "units", "comment"])
def test_valid_variants_give_identical_numbers(tmp_path, seed, variant):
    head, rows = _plain(seed)
    ref = read_table(_write(tmp_path / "plain.csv", head, rows), SPEC)
    kw = {}
    h = list(head)
    if "bom" in variant:
        kw["bom"] = True
    if "crlf" in variant:
        kw["crlf"] = True
    if variant == "caps":
        h = [x.upper() for x in h]
    if variant == "spaces":
        h = [f"  {x} " for x in h]
        rows = [[f" {v}" if k else v for k, v in enumerate(r)] for r in rows]
    if variant == "semicolon":
        kw["sep"] = ";"
    if variant == "tab":
        kw["sep"] = "\t"
    if variant == "reordered":
        kw["order"] = [5, 3, 0, 2, 4, 1]
    if variant == "aliases":
        h = ["Label", "AX", "ay", "Az", "n", "Time"]
    if variant == "units":
        h = ["pose", "ux [V]", "uy [V]", "uz (V)", "n", "t (s)"]
    p = _write(tmp_path / "v.csv", h, rows, **kw)
    if variant == "comment":
        p.write_text("# exported by a logger\n# second comment\n" + p.read_text())
    got = read_table(p, SPEC)
    assert set(got.data) == set(ref.data)
    for k in ref.data:
        if ref[k].dtype == object:
            assert [s.strip() for s in got[k]] == list(ref[k])
        else:
            assert np.array_equal(got[k], ref[k]), k
    if variant == "units":
        assert got.units == {"ux": "V", "uy": "V", "uz": "V", "t": "s"}


def test_column_map_and_ignored_columns(tmp_path):
    head, rows = _plain(1)
    ref = read_table(_write(tmp_path / "a.csv", head, rows), SPEC)
    h2 = ["pose", "acc1", "acc2", "acc3", "n", "t"]
    p = _write(tmp_path / "b.csv", h2 + ["extra"], [r + ["9"] for r in rows])
    with pytest.raises(InputError, match=r"b.csv:1: header: .* lacks ux, uy, uz.*--columns"):
        read_table(p, SPEC)
    got = read_table(p, SPEC, parse_column_map("ux=acc1, uy=ACC2,uz=acc3"))
    assert np.array_equal(got["ux"], ref["ux"]) and got.ignored == ("extra",)
    with pytest.raises(InputError, match="--columns.*not NAME=HEADER"):
        parse_column_map("ux:acc1")
    with pytest.raises(InputError, match="--columns: vx not a column"):
        read_table(p, SPEC, {"vx": "acc1"})
    with pytest.raises(InputError, match="no such column"):
        read_table(p, SPEC, {"ux": "nope", "uy": "acc2", "uz": "acc3"})


def test_streamed_chunks_equal_the_whole_table(tmp_path):
    labels, u, t, n = _rows(4, n=20000)
    p = tmp_path / "big.csv"
    p.write_text("ux,uy,uz,n,t\n" + "\n".join(
        f"{float(a)!r},{float(b)!r},{float(c)!r},{k},{float(s)!r}"
        for (a, b, c), k, s in zip(u, n, t, strict=True)))
    whole = read_table(p, SPEC)
    chunks = list(iter_table(p, SPEC, block_bytes=1 << 16))
    assert len(chunks) > 3
    for k in whole.data:
        assert np.array_equal(np.concatenate([c[k] for c in chunks]), whole[k])
    # A time step backwards in a later chunk names its line.
    lines = p.read_text().splitlines()
    i = 15000
    f = lines[i].split(",")
    f[4] = lines[i - 2].split(",")[4]
    lines[i] = ",".join(f)
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=rf"big.csv:{i + 1}: t: .* runs backwards"):
        for _ in iter_table(p, SPEC, block_bytes=1 << 16):
            pass


@pytest.mark.parametrize("text, match", [
    ("", "empty file"),
    ("# only a comment\n", "empty file"),
    ("ux,uy,uz\n", "no rows under it"),
    ("ux,uy,uz\n1,2,3\n1,2\n", r":3: 2 fields, the header has 3"),
    ("ux,uy,uz\n1,2,3\n1,x,3\n", r":3: uy: 'x' is not a number"),
    ("ux;uy;uz\n1;2,5;3\n", r":2: uy: '2,5' is not a number \(a decimal comma"),
    ("ux,uy,uz\n1,2,3\n1,nan,3\n", r":3: uy: .* not a finite number"),
    ("ux,uy,uz\n1,2,3\n1,inf,3\n", r":3: uy: .* not a finite number"),
    ("ux,uy,uz\n1,2,3\n1,,3\n", r":3: uy: is empty"),
    ("pose,ux,uy,uz\na,1,2,3\n,1,2,3\n", r":3: pose: is blank"),
    ("pose,ux,uy,uz\na,1,2,3\n  ,1,2,3\n", r":3: pose: is blank"),
    ("ux,uy,uz,n\n1,2,3,4\n1,2,3,4.5\n", r":3: n: '4.5' is not a whole number"),
    ("ux,uy,uz,t\n1,2,3,0.1\n1,2,3,0.1\n", r":3: t: .* repeats the previous row's time"),
    ("ux,uy,uz,t\n1,2,3,0.2\n\n1,2,3,0.1\n", r":4: t: .* runs backwards"),
    ("ux,ux,uy,uz\n1,2,3,4\n", r":1: header: ux: given 2 times"),
    ("ux,uy,uz,ax\n1,2,3,4\n", r"given 2 times"),
    ("pose,uy,uz\n1,2,3\n", r"lacks ux"),
])
def test_bad_tables_name_file_line_column(tmp_path, text, match):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(InputError, match=match):
        read_table(p, SPEC)


def test_unreadable_files(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_table(tmp_path / "nope.csv", SPEC)
    with pytest.raises(InputError, match="is a folder"):
        read_table(tmp_path, SPEC)
    p = tmp_path / "bin.csv"
    p.write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe\x00")
    with pytest.raises(InputError, match="not a UTF-8 text file"):
        read_table(p, SPEC)


def test_rate_makes_the_time_column(tmp_path):
    p = tmp_path / "r.csv"
    p.write_text("ux,uy,uz\n" + "\n".join(f"{k},{k},{k}" for k in range(10)))
    tab = read_table(p, SPEC, rate_hz=50.0)
    assert np.allclose(tab["t"], np.arange(10) / 50.0) and tab.time_from_rate
    with pytest.raises(InputError, match="--rate -1: must be a positive"):
        read_table(p, SPEC, rate_hz=-1.0)
    with pytest.raises(InputError, match="--rate nan"):
        read_table(p, SPEC, rate_hz=float("nan"))
    q = tmp_path / "q.csv"
    q.write_text("ux,uy,uz,t\n1,2,3,0\n")
    with pytest.raises(InputError, match="has its own time column"):
        read_table(q, SPEC, rate_hz=10.0)


def test_quantised_counts_with_chance_repeats_are_not_duplicates(tmp_path):
    """Raw ADC counts with a noise of about one count repeat row by row by chance; a file
    that is constant has every row equal. Neither is refused as duplicated; a real
    duplication (each row written twice, or the file twice) is."""
    from axisbase.errors import InputError as Err

    rng = np.random.default_rng(5)
    n = 400
    counts = np.round(rng.normal([1000, -20, 3], 0.4, (n, 3))).astype(int)
    assert (counts[1:] == counts[:-1]).all(axis=1).mean() > 0.2  # many chance repeats
    spec = TableSpec("readings file", tuple(Column(c) for c in ("ux", "uy", "uz")),
                     distinct_rows=True)

    def save(rows, name):
        p = tmp_path / name
        p.write_text("ux,uy,uz\n" + "".join(f"{a},{b},{c}\n" for a, b, c in rows))
        return p

    assert len(read_table(save(counts, "ok.csv"), spec)) == n
    assert len(read_table(save(np.ones((50, 3), int), "const.csv"), spec)) == 50
    with pytest.raises(Err, match="written twice"):
        read_table(save(np.repeat(counts[:100], 2, axis=0), "pairs.csv"), spec)
    with pytest.raises(Err, match=r"block\.csv:102: lines 102-201 repeat lines 2-101 exactly"
                                  r".*written twice\? keep one copy"):
        read_table(save(np.concatenate([counts[:100], counts[:100]]), "block.csv"), spec)


def test_one_poses_rows_pasted_twice_are_refused_naming_both_blocks(tmp_path):
    """A block of rows pasted again elsewhere (one pose's 200 samples of a 14-pose file)
    shrinks that pose's u by sqrt 2 without adding information: refused, naming the lines of
    both copies. Clean noisy poses, quantised counts with chance repeats and a stuck stretch
    are read as they are."""
    from axisbase.errors import InputError as Err

    rng = np.random.default_rng(11)
    poses = [f"P{k:02d}" for k in range(14)]
    rows = [(p, *rng.normal(0, 1e-3, 3) + rng.normal(0, 1, 3)) for p in poses
            for _ in range(200)]
    spec = TableSpec("static poses", (Column("pose", "label"),
                                      *(Column(c) for c in ("ux", "uy", "uz"))),
                     distinct_rows=True)

    def save(rs, name):
        p = tmp_path / name
        p.write_text("pose,ux,uy,uz\n" + "".join(f"{a},{b:.9e},{c:.9e},{d:.9e}\n"
                                                  for a, b, c, d in rs))
        return p

    assert len(read_table(save(rows, "clean.csv"), spec)) == len(rows)
    pasted = rows[:1400] + rows[1200:1400] + rows[1400:]  # pose P06 twice, back to back
    with pytest.raises(Err, match=r"pasted\.csv:1402: lines 1402-1601 repeat lines 1202-1401"):
        read_table(save(pasted, "pasted.csv"), spec)
    elsewhere = rows + rows[400:600]  # P02 again at the end
    with pytest.raises(Err, match=r"lines 2802-3001 repeat lines 402-601 exactly .*pasted again"):
        read_table(save(elsewhere, "elsewhere.csv"), spec)
    stuck = list(rows)
    stuck[600:700] = [rows[600]] * 100  # a stuck stretch repeats itself: not a paste
    assert len(read_table(save(stuck, "stuck.csv"), spec)) == len(rows)
    counts = np.round(rng.normal([1000, -20, 3], 0.4, (3000, 3))).astype(int)
    spec3 = TableSpec("readings file", tuple(Column(c) for c in ("ux", "uy", "uz")),
                      distinct_rows=True)
    q = tmp_path / "counts.csv"
    q.write_text("ux,uy,uz\n" + "".join(f"{a},{b},{c}\n" for a, b, c in counts))
    assert len(read_table(q, spec3)) == 3000


@pytest.mark.parametrize("comment", ["# paused", "#", "  # indented", "# a, b, c", "# 1,2,3,4,5",
                                     "# gain,2,3,4,5,6", "# x,y,z,w,v,u",
                                     '#a,"open quote', "# x,y,z,w,v,u,t,s"])
def test_comment_lines_anywhere_are_ignored(tmp_path, comment):
    """Whatever the comment holds (no delimiter, fewer, as many or more fields than the
    header, a quote it never closes), whole and streamed reads give the plain file's rows,
    and a bad row after the comments is still named by its own line."""
    head, rows = _plain(5)
    lines = [",".join(r) for r in rows]
    plain = read_table(_write(tmp_path / "plain.csv", head, rows), SPEC)
    text = [",".join(head), comment, *lines[:20], comment, comment, *lines[20:], comment]
    p = tmp_path / "c.csv"
    p.write_text("\n".join(text) + "\n")
    chunks = list(iter_table(p, SPEC, block_bytes=1 << 10))
    assert len(chunks) > 1
    whole = read_table(p, SPEC)
    for k in plain.data:
        assert np.array_equal(whole[k], plain[k]), (comment, k)
        assert np.array_equal(np.concatenate([c[k] for c in chunks]), plain[k]), (comment, k)
    bad = list(text)
    bad[40] = "p9,1,x,3,4,5"
    p.write_text("\n".join(bad) + "\n")
    for read in (lambda: read_table(p, SPEC),
                 lambda: list(iter_table(p, SPEC, block_bytes=1 << 10))):
        with pytest.raises(InputError, match=r"c\.csv:41: uy: 'x' is not a number"):
            read()
    short = list(text)
    short[45] = "p9,1,2"
    p.write_text("\n".join(short) + "\n")
    with pytest.raises(InputError, match=r"c\.csv:46: 3 fields, the header has 6"):
        read_table(p, SPEC)


def test_a_comment_never_swallows_rows(tmp_path):
    """A comment opening a quote the parser would carry over the next lines is not skipped
    with them: those rows are read (or named if bad)."""
    p = tmp_path / "q.csv"
    p.write_text('ux,uy,uz\n1,2,3\n#"a\n4,5,6\n7,8,9\n')
    assert read_table(p, SPEC)["ux"].tolist() == [1.0, 4.0, 7.0]
    p.write_text('ux,uy,uz\n1,2,3\n#"a\n4,5,6\n7,8"\n')
    with pytest.raises(InputError, match=r"q\.csv:5: 2 fields"):
        read_table(p, SPEC)


# ----------------------------------------------------------------------------- parallel parse

NUM_SPEC = TableSpec("number table", (
    Column("ux"), Column("uy"), Column("n", "int"), Column("t", required=False)), time="t")


def _numbers(seed: int, n: int = 400) -> tuple[list[str], list[list[str]]]:
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 2)) * 10 ** rng.uniform(-6, 3)
    t = np.cumsum(rng.uniform(0.001, 0.1, n))
    return ["ux", "uy", "n", "t"], [[repr(float(a)), repr(float(b)), str(k), repr(float(s))]
                                    for (a, b), k, s in zip(u, rng.integers(-9, 9, n), t,
                                                            strict=True)]


def _dialect(path, head, rows, variant: str):
    sep = {"semicolon": ";", "tab": "\t"}.get(variant, ",")
    nl = {"crlf": "\r\n", "cr": "\r"}.get(variant, "\n")
    lines = [sep.join(head)] + [sep.join(r) for r in rows]
    if variant == "comments":  # comments and blank lines between rows, anywhere
        for i in (3, 50, 51, 200, 399):
            lines.insert(i, "# paused" if i % 2 else "")
    text = nl.join(lines) + ("" if variant == "no-final-newline" else nl)
    path.write_bytes((b"\xef\xbb\xbf" if variant == "bom" else b"") + text.encode())
    return path


@pytest.mark.parametrize("block", [64, 700, 1 << 20])
@pytest.mark.parametrize("variant", ["plain", "crlf", "cr", "bom", "semicolon", "tab",
                                     "comments", "no-final-newline"])
def test_parallel_parse_gives_the_serial_numbers_and_lines(tmp_path, monkeypatch, block,
                                                           variant):
    """Blocks cut anywhere (64 bytes: every few rows; 1 MiB: one block), in every dialect:
    the same numbers as the serial reader, in the same order, and the same line for a row."""
    import axisbase.csvblocks as csvblocks

    monkeypatch.setattr(csvblocks, "PARALLEL_BLOCK", block)
    head, rows = _numbers(7)
    p = _dialect(tmp_path / f"{variant}.csv", head, rows, variant)
    serial = list(iter_table(p, NUM_SPEC, block_bytes=1 << 10))
    par = list(iter_table(p, NUM_SPEC, block_bytes=1 << 10, parallel=True))
    for k in ("ux", "uy", "n", "t"):
        a = np.concatenate([c[k] for c in serial])
        assert np.array_equal(a, np.concatenate([c[k] for c in par])), k
        assert len(a) == len(rows)
    # the row -> line mapping of a chunk deep in the file
    c = par[len(par) // 2]
    s = next(s for s in serial if s.row0 <= c.row0 < s.row0 + len(s))
    assert c.line(0) == s.line(c.row0 - s.row0)


@pytest.mark.parametrize("block", [64, 700])
@pytest.mark.parametrize("edit, match", [
    (lambda f: f.__setitem__(1, "x"), r":{line}: uy: 'x' is not a number"),
    (lambda f: f.__setitem__(2, "4.5"), r":{line}: n: '4.5' is not a whole number"),
    (lambda f: f.__setitem__(3, "0.0001"), r":{line}: t: .* runs backwards"),
    (lambda f: f.pop(), r":{line}: 3 fields, the header has 4"),
    (lambda f: f.__setitem__(0, "1,5"), r":{line}: 5 fields, the header has 4"),
])
def test_parallel_parse_names_the_same_bad_line(tmp_path, monkeypatch, block, edit, match):
    """A bad row in a later block is named by its own line, as the serial reader names it."""
    import axisbase.csvblocks as csvblocks

    monkeypatch.setattr(csvblocks, "PARALLEL_BLOCK", block)
    head, rows = _numbers(3)
    i = 317
    f = list(rows[i])
    edit(f)
    rows[i] = f
    p = _dialect(tmp_path / "bad.csv", head, rows, "plain")
    for parallel in (False, True):
        with pytest.raises(InputError, match=match.format(line=i + 2)):
            list(iter_table(p, NUM_SPEC, block_bytes=1 << 10, parallel=parallel))


def test_parallel_reader_stopped_early_leaves_no_thread(tmp_path, monkeypatch):
    import threading

    import axisbase.csvblocks as csvblocks

    monkeypatch.setattr(csvblocks, "PARALLEL_BLOCK", 256)
    head, rows = _numbers(2, n=3000)
    p = _dialect(tmp_path / "long.csv", head, rows, "plain")
    before = threading.active_count()
    it = iter_table(p, NUM_SPEC, block_bytes=512, parallel=True)
    assert len(next(it)) > 0
    it.close()
    assert threading.active_count() == before
    with pytest.raises(ValueError, match="numbers only"):
        next(iter_table(p, SPEC, parallel=True))


# ------------------------------------------------- declared time unit, logger's meta lines

@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("unit, scale", [("us", 1e-6), ("ms", 1e-3), ("s", 1.0)])
def test_declared_time_unit_reads_as_the_header_unit_would(tmp_path, seed, unit, scale):
    """A plain 't' in µs with time_unit='us' gives the numbers 't [us]' gives, in seconds;
    read whole and streamed alike."""
    head, rows = _plain(seed)
    rows = [r[:5] + [repr(float(r[5]) / scale)] for r in rows]
    plain = _write(tmp_path / "p.csv", head, rows)
    said = _write(tmp_path / "s.csv", head[:5] + [f"t [{unit}]"], rows)
    a, b = read_table(plain, SPEC, time_unit=unit), read_table(said, SPEC)
    assert np.array_equal(a["t"], b["t"])
    assert np.allclose(a["t"], _rows(seed)[2], rtol=1e-12)  # the truth, in seconds
    c = np.concatenate([ch["t"] for ch in iter_table(plain, SPEC, block_bytes=256,
                                                     time_unit=unit)])
    assert np.array_equal(c, a["t"])


def test_declared_time_unit_refused_when_the_header_disagrees_or_it_is_no_unit(tmp_path):
    p = tmp_path / "m.csv"
    p.write_text("# a comment\nux,uy,uz,t [ms]\n1,2,3,0\n1,2,3,5\n")
    with pytest.raises(InputError, match=r"m\.csv:2: t: the header says \[ms\].*--time-unit"):
        read_table(p, SPEC, time_unit="us")
    assert np.allclose(read_table(p, SPEC, time_unit="ms")["t"], [0, 0.005])  # agreeing
    with pytest.raises(InputError, match="--time-unit / time_unit 'parsec': not a time unit"):
        read_table(p, SPEC, time_unit="parsec")



def test_declared_time_unit_applies_to_rows_in_memory_by_the_same_rule():
    """Rows in memory under a plain 't' take the declared unit as a file's header does; a
    name that says another unit is refused naming the rows and the flag/key."""
    from axisbase.table import iter_rows

    rows = {"ux": [1.0, 1.0], "uy": [2.0, 2.0], "uz": [3.0, 3.0], "t": [0.0, 5000.0]}
    got = next(iter_rows(rows, SPEC, time_unit="us"))["t"]
    assert np.allclose(got, [0, 0.005], rtol=1e-15)
    assert np.allclose(next(iter_rows(rows, SPEC))["t"], [0, 5000])  # seconds by default
    said = {**{k: v for k, v in rows.items() if k != "t"}, "t [ms]": rows["t"]}
    with pytest.raises(InputError, match=r"rows: column names: t: the header says \[ms\]"
                       r".*--time-unit / time_unit"):
        next(iter_rows(said, SPEC, time_unit="us"))


@pytest.mark.parametrize("meta", [["Fs,100", "Logging Type,0", "Initialization time,36.5",
                                   "Waiting time,3"],
                                  ["sensor;MPU-6050", "", "# note", "gain;2 g"]])
def test_meta_lines_before_the_header_are_skipped_and_said(tmp_path, caplog, meta):
    """A logger's settings before the header: the same numbers as without them, a note
    naming the lines skipped; a file whose later lines never hold the columns keeps the
    first line's error."""
    head, rows = _plain(4)
    clean = _write(tmp_path / "c.csv", head, rows)
    p = tmp_path / "m.csv"
    p.write_text("\n".join(meta) + "\n" + clean.read_text())
    with caplog.at_level("WARNING", logger="align"):
        tab = read_table(p, SPEC)
    ref = read_table(clean, SPEC)
    for k in ("ux", "uy", "uz", "t", "n"):
        assert np.array_equal(tab[k], ref[k])
    assert list(tab["pose"]) == list(ref["pose"])
    skipped = sum(1 for m in meta if m.strip() and not m.startswith("#"))
    assert f"{skipped} line(s) before the header at line {len(meta) + 1} skipped" in caplog.text
    chunks = list(iter_table(p, SPEC, block_bytes=512))
    assert np.array_equal(np.concatenate([c["ux"] for c in chunks]), ref["ux"])
    # a bad row is named at its own line in the file (meta lines counted)
    lines = p.read_text().splitlines()
    lines[len(meta) + 3] = lines[len(meta) + 3].replace(",", ",x", 1)
    p.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=rf"m\.csv:{len(meta) + 4}:"):
        read_table(p, SPEC)
    q = tmp_path / "none.csv"
    q.write_text("Fs,100\nfoo,bar,baz\n1,2,3\n")
    with pytest.raises(InputError, match=r"none\.csv:1: header: \(Fs, 100\) lacks ux"):
        read_table(q, SPEC)


def test_real_openaxes_log_with_microsecond_times_reads_directly():
    """The OpenAXES log: ';'-separated, TIME in µs with no unit in its header. Declared
    'us', it reads at the logger's ~100 Hz with no implausible-rate warning (read as
    seconds: 9e-5 Hz and the warning names us)."""
    path = real_folder("openaxes-imu9") / "log_imu9_2022-06-22_22-13-55.csv"
    cols = parse_column_map("ux=ACCEL_ADXL355_0,uy=ACCEL_ADXL355_1,uz=ACCEL_ADXL355_2")
    tab = read_table(path, STATIC, cols, time_unit="us")
    dt = float(np.median(np.diff(tab["t"])))
    assert 1e-3 < dt < 0.1 and rate_warning(tab) is None, dt
    assert "us" in rate_warning(read_table(path, STATIC, cols))
    assert len(tab) == len(path.read_text().splitlines()) - 1


def test_real_mpu6050_csv_with_four_meta_lines_reads_directly(caplog):
    """The MPU-6050 CSV: 'Fs,100' and three more settings lines before its header."""
    path = real_folder("mpu6050-tomisuarez") / "example_data_calibration.csv"
    with caplog.at_level("WARNING", logger="align"):
        tab = read_table(path, STATIC, rate_hz=100.0)
    lines = path.read_text().splitlines()
    assert len(tab) == len(lines) - 5
    assert list(tab["ux"][:3]) == [float(v.split(",")[0]) for v in lines[5:8]]
    assert "4 line(s) before the header at line 5 skipped" in caplog.text


# ------------------------------------------------------------- temperature column's unit

@pytest.mark.parametrize(("unit", "to_unit"), [
    ("K", lambda k: k), ("kelvin", lambda k: k), ("degC", lambda k: k - 273.15),
    ("°C", lambda k: k - 273.15), ("C", lambda k: k - 273.15),
    ("F", lambda k: (k - 273.15) * 1.8 + 32), ("°F", lambda k: (k - 273.15) * 1.8 + 32),
    ("degF", lambda k: (k - 273.15) * 1.8 + 32)])
def test_temperature_header_unit_is_converted_to_kelvin(tmp_path, unit, to_unit):
    """The same temperatures (290-300 K) written in K, °C or °F read back in kelvin (to the
    rounding of the written digits); a plain ``temp`` column is carried as written."""
    kelvin = np.linspace(290.0, 300.0, 12)
    rows = "".join(f"p{i},1,2,3,{to_unit(k):.6f}\n" for i, k in enumerate(kelvin))
    f = tmp_path / "s.csv"
    f.write_text(f"pose,ux,uy,uz,temp [{unit}]\n" + rows)
    tab = read_table(f, STATIC)
    assert np.allclose(tab["temp"], kelvin, atol=2e-6) and tab.units["temp"] == "K"
    f.write_text("pose,ux,uy,uz,temp\n" + rows)
    assert np.allclose(read_table(f, STATIC)["temp"], [to_unit(k) for k in kelvin], atol=1e-6)


def test_temperature_in_an_unknown_unit_is_refused_naming_file_column_and_unit(tmp_path):
    f = tmp_path / "s.csv"
    f.write_text("pose,ux,uy,uz,temp [Ra]\np0,1,2,3,540\n")
    with pytest.raises(InputError) as e:
        read_table(f, STATIC)
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"{f}:1: temp: temperature unit 'Ra' not known")
    assert "K, degC, degF" in msg
