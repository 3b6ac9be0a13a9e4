"""Writes jsss/data/materials.json (run from this folder after parse_sources.py; the
library's provenance is in the file itself)."""
import json, re
d = json.load(open("raw.json"))
v4, mi = d["v4"], d["mi"]
PBRT4 = "5f7a606806a4ac7b939131ded9d7a30ebd02416e"
MITSUBA = "10af06f365886c1b6dd8818e0a3841078a62f283"
jensen_rd = {  # Jensen 2001 Fig. 5(b) 'Diffuse Reflectance' and eta (shared/papers/jensen2001-practical-model.txt)
    "Apple": ((0.85, 0.84, 0.53), 1.3), "Chicken1": ((0.31, 0.15, 0.10), 1.3), "Chicken2": ((0.32, 0.16, 0.10), 1.3),
    "Cream": ((0.98, 0.90, 0.73), 1.3), "Ketchup": ((0.16, 0.01, 0.00), 1.3), "Marble": ((0.83, 0.79, 0.75), 1.5),
    "Potato": ((0.77, 0.62, 0.21), 1.3), "Skimmilk": ((0.81, 0.81, 0.69), 1.3), "Skin1": ((0.44, 0.22, 0.13), 1.3),
    "Skin2": ((0.63, 0.44, 0.34), 1.3), "Spectralon": ((1.00, 1.00, 1.00), 1.3), "Wholemilk": ((0.91, 0.88, 0.76), 1.3)}
mi_alias = {"Budweiser Beer": "Budweiser Beder", "Orange Powder": "Orange Juice Powder"}

def key(label):
    return re.sub(r"[^a-z0-9]+", "_", label.lower().replace("&", "and")).strip("_")

sources = {
    "jensen2001": {
        "short": "Jensen 2001",
        "citation": "H. W. Jensen, S. R. Marschner, M. Levoy, P. Hanrahan. A Practical Model for Subsurface "
                    "Light Transport. Proc. SIGGRAPH 2001.",
        "table": "Fig. 5(b), 'measured parameters for several materials'",
        "units": "sigma_s' and sigma_a in mm^-1 for the R, G, B bands of a 3-CCD camera, as the paper prints them",
        "conversion": "none: the paper gives sigma_s' (reduced) and sigma_a in 1/mm",
        "g": "not given: the measurement (a beam profile fitted with the dipole, sec. 3) determines sigma_s' only; "
             "stored as 0, for which sigma_s = sigma_s'",
        "eta": "the paper's column eta ('empirical values for the index of refraction for most of the materials', sec. 3)",
        "uncertainty": "no numbers; sec. 3: 'the parameters for the relatively opaque materials (such as the blue "
                       "wavelength in ketchup) may be less accurate'",
        "transcribed_from": "the paper's text (shared/papers/jensen2001-practical-model.txt); identical to "
                            f"pbrt-v4 src/pbrt/media.cpp @ {PBRT4[:12]}",
    },
    "narasimhan2006": {
        "short": "Narasimhan 2006",
        "citation": "S. G. Narasimhan, M. Gupta, C. Donner, R. Ramamoorthi, S. K. Nayar, H. W. Jensen. "
                    "Acquiring Scattering Properties of Participating Media by Dilution. Proc. SIGGRAPH 2006.",
        "table": "the paper's table of measured parameters (at the dilution measured), scaled to natural concentration as "
                 "pbrt-v4 and Mitsuba 0.5 tabulate it; the paper itself was not reachable",
        "units": "1/mm at natural concentration, R, G, B (pbrt-v4's comment: 'mm^-1'; Mitsuba 0.5's docs: "
                 "'They all use units of 1/mm')",
        "conversion": "sigma_a and sigma_s' = sigma_s (1 - g) as pbrt-v4 prints them (its field 'sigma_prime_s'); "
                      "sigma_s and the per-channel Henyey-Greenstein g as Mitsuba 0.5 prints them; "
                      "sigma_s (1 - g) reproduces pbrt-v4's sigma_s' to the digits printed "
                      "(tests/jsss/test_materials.py)",
        "g": "Mitsuba 0.5's per-channel g (src/medium/materials.h: 'From \"Acquiring Scattering Properties of "
             "Participating Media by Dilution\"'); a channel without measurable scattering (sigma_s = 0) has g = 0 "
             "there, which means nothing",
        "eta": "not given by either renderer's source; 1.33 assumed (water-based liquids and powders dissolved "
               "in water; Mitsuba 0.5 uses 1.33 for every one)",
        "uncertainty": "not given in the sources read (the paper itself was not reachable; pbrt and Mitsuba give "
                       "none); values quoted to 3-6 significant digits",
        "transcribed_from": f"pbrt-v4 src/pbrt/media.cpp @ {PBRT4[:12]} (Apache-2.0) for sigma_a and sigma_s'; "
                            f"Mitsuba 0.5 src/medium/materials.h @ {MITSUBA[:12]} (GPL-3.0; numbers only) for "
                            "sigma_s and g; checked against pbrt-v2 src/core/volume.cpp (the paper's diluted "
                            "table) in tests/jsss/test_materials.py",
    },
}
materials = []
names = list(v4)
for label in names[:12]:
    sp, sa = v4[label]
    rd, eta = jensen_rd[label]
    materials.append({"name": key(label), "label": label, "source": "jensen2001", "sigma_a": sa,
                      "sigma_s_prime": sp, "sigma_s": None, "g": [0.0, 0.0, 0.0], "eta": eta,
                      "diffuse_reflectance": list(rd)})
for label in names[12:]:
    sp, sa = v4[label]
    ms, ma, g, eta = mi[mi_alias.get(label, label)]
    entry = {"name": key(label), "label": label, "source": "narasimhan2006", "sigma_a": sa, "sigma_s_prime": sp,
             "sigma_s": ms, "g": g, "eta": 1.33}
    if label in mi_alias:
        entry["note"] = f"Mitsuba 0.5 spells it {mi_alias[label]!r}"
    zero = [c for c, s in zip("RGB", sp) if s == 0]
    if zero:
        entry["note"] = (entry.get("note", "") + "; " if "note" in entry else "") + (
            f"no measurable scattering in {', '.join(zero)} (sigma_s = 0 in both sources): that channel returns no "
            "diffuse light")
    materials.append(entry)
assert len({m["name"] for m in materials}) == len(materials)
out = {"about": "Measured homogeneous materials with provenance; read by jsss.materials. Lengths in mm, "
                "coefficients in 1/mm, RGB.", "sources": sources, "materials": materials}
text = json.dumps(out, indent=1)
# one material per line keeps the table readable
text = re.sub(r"\[\s+([^\[\]{}]*?)\s+\]", lambda m: "[" + " ".join(m.group(1).split()) + "]", text)
open(__import__("pathlib").Path(__file__).resolve().parents[2] / "jsss" / "data" / "materials.json", "w").write(text + "\n")
print(len(materials), [m["name"] for m in materials])
