"""map.json and contacts.csv: round trips and the errors a user sees for bad files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wholearm_tools.contact_table import ContactTable, read_contact_table, write_contact_table
from wholearm_tools.errors import InputError
from wholearm_tools.mapfile import MappedPrimitive, SurfaceMap, read_map, write_map


def sample_map() -> SurfaceMap:
    cyl = MappedPrimitive(
        id=0, kind="cylinder",
        params={"point": np.array([0.0, 0.0, 0.45]), "axis": np.array([0.0, 0.0, 1.0]),
                "radius": 0.15},
        ci95={"point": np.array([1e-3, 1e-3, 0.0]), "axis": np.array([2e-3, 2e-3, 0.0]),
              "radius": 6e-4},
        covariance=np.eye(7) * 1e-8, support={"tip": 14, "link": 6}, rms_residual=4e-4,
        extent={"s": [-0.3, 0.4], "angle": {"reference": [1, 0, 0], "start": 0.0,
                                            "sweep": 2 * np.pi, "full": True}})
    return SurfaceMap(planar=False, B=0.02, primitives=(cyl,),
                      contacts={"count": 20, "tip": 14, "link": 6},
                      unexplained=np.array([[0.1, 0.2, 0.3]]), meta={"source": "run.mcap"})


def test_map_round_trip(tmp_path) -> None:
    path = tmp_path / "map.json"
    write_map(path, sample_map())
    back = read_map(path)
    prim = back.primitives[0]
    assert prim.kind == "cylinder"
    assert prim.params["radius"] == pytest.approx(0.15)
    np.testing.assert_allclose(prim.params["axis"], [0, 0, 1])
    assert prim.support == {"tip": 14, "link": 6}
    assert prim.primitive.radius == pytest.approx(0.15)
    np.testing.assert_allclose(back.unexplained, [[0.1, 0.2, 0.3]])
    assert json.loads(path.read_text())["format"] == "wholearm-map"
    assert path.stat().st_mode & 0o777 != 0o600  # usual permissions, not mkstemp's


def test_map_errors_name_file_and_problem(tmp_path) -> None:
    path = tmp_path / "map.json"
    data = sample_map().to_json()
    path.write_text(json.dumps({**data, "version": 2}))
    with pytest.raises(InputError, match=r"map\.json: map version 2 is not supported"):
        read_map(path)
    path.write_text(json.dumps({**data, "format": "something-else"}))
    with pytest.raises(InputError, match="not a wholearm map"):
        read_map(path)
    path.write_text('{"format": "wholearm-map", "version": 1, "planar": false}')
    with pytest.raises(InputError, match="malformed map"):
        read_map(path)
    path.write_text("{not json")
    with pytest.raises(InputError, match="malformed JSON"):
        read_map(path)
    with pytest.raises(InputError, match="cannot read map"):
        read_map(tmp_path / "missing.json")


def sample_table(dim: int = 2) -> ContactTable:
    rng = np.random.default_rng(0)
    m = 5
    a = rng.normal(size=(m, dim))
    return ContactTable(
        t=np.arange(m) * 1.5, link=np.array([0, 1, 1, 0, 1]),
        p_tip=np.array([0.9, 0.1, 0.5, 0.0, 1.0]),
        label=np.array(["tip", "link", "ambiguous", "link", "tip"]),
        variance=np.full(m, 1e-6), used_as_tip=np.array([True, False, True, False, True]),
        tip_center=a + 1, tip_radius=np.full(m, 0.015), seg_a=a, seg_b=a + 1,
        link_radius=np.full(m, 0.01), primitive=np.array([0, 0, 1, -1, 1]),
        residual=np.array([1e-4, -2e-4, 3e-5, np.nan, 0.0]),
        p_tip_map=np.array([0.99, 0.01, np.nan, 0.0, 1.0]),
        label_map=np.array(["tip", "link", "", "link", "tip"]),
        link_by_map=np.array([0, 2, -1, 0, 1]),
        t_settle=np.arange(m) * 1.5 + 0.2, t_end=np.array([0.5, 2.0, np.nan, 5.0, 6.5]),
        p_link=np.array([1.0, 0.55, 0.45, 1.0, 0.9]))


@pytest.mark.parametrize("dim", [2, 3])
def test_contact_table_csv_round_trip(tmp_path, dim: int) -> None:
    table = sample_table(dim)
    path = tmp_path / "contacts.csv"
    write_contact_table(path, table)
    back = read_contact_table(path)
    assert back.dim == dim
    np.testing.assert_allclose(back.tip_center, table.tip_center, rtol=1e-8)
    np.testing.assert_array_equal(back.label, table.label)
    np.testing.assert_array_equal(back.used_as_tip, table.used_as_tip)
    np.testing.assert_array_equal(back.primitive, table.primitive)
    np.testing.assert_allclose(back.residual, table.residual, equal_nan=True)
    np.testing.assert_allclose(back.p_tip_map, table.p_tip_map, equal_nan=True)
    np.testing.assert_array_equal(back.label_map, table.label_map)
    np.testing.assert_array_equal(back.link_by_map, table.link_by_map)
    np.testing.assert_allclose(back.t_settle, table.t_settle)
    np.testing.assert_allclose(back.t_end, table.t_end, equal_nan=True)
    np.testing.assert_allclose(back.p_link, table.p_link)


def test_contact_table_without_event_times_reads_them_as_unknown(tmp_path) -> None:
    """A table written before the event columns (or by hand) still reads: its contacts are
    moments at ``t``, and scoring pairs them by time alone."""
    header, rows = sample_table().rows()
    keep = [h for h in header if h not in ("t_settle", "t_end", "p_link")]
    path = tmp_path / "contacts.csv"
    path.write_text(",".join(keep) + "\n"
                    + "\n".join(",".join(r[h] for h in keep) for r in rows) + "\n")
    back = read_contact_table(path)
    assert np.all(np.isnan(back.t_settle))
    assert np.all(np.isnan(back.t_end))
    assert np.all(np.isnan(back.p_link))


def test_contact_table_errors(tmp_path) -> None:
    path = tmp_path / "contacts.csv"
    path.write_text("t,link\n")
    with pytest.raises(InputError, match="no contacts"):
        read_contact_table(path)
    path.write_text("t,link,p_tip\n1,0,0.5\n")
    with pytest.raises(InputError, match="missing columns"):
        read_contact_table(path)
    text = sample_table().to_csv().replace("0.015", "nan", 1)
    path.write_text(text)
    with pytest.raises(InputError, match="tip_radius has NaN"):
        read_contact_table(path)
    path.write_text(sample_table().to_csv().replace(",tip,", ",maybe,", 1))
    with pytest.raises(InputError, match="unknown contact labels"):
        read_contact_table(path)
    header, rows = sample_table().rows()
    rows[1]["p_link"] = "1.5"
    path.write_text(",".join(header) + "\n"
                    + "\n".join(",".join(r[h] for h in header) for r in rows) + "\n")
    with pytest.raises(InputError, match="p_link must lie in"):
        read_contact_table(path)
    path.write_text(sample_table().to_csv().replace(",0.990000,", ",often,", 1))
    with pytest.raises(InputError, match="bad value in column 'p_tip_map'"):
        read_contact_table(path)
    header, rows = sample_table().rows()
    for column in ("primitive", "link_by_map"):
        bad = [dict(r) for r in rows]
        bad[0][column] = "two"
        path.write_text(",".join(header) + "\n"
                        + "\n".join(",".join(r[h] for h in header) for r in bad) + "\n")
        with pytest.raises(InputError, match=f"bad value in column '{column}'") as err:
            read_contact_table(path)
        assert str(err.value).count(str(path)) == 1  # the file named once
