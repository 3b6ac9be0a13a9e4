"""Extract the media tables of pbrt-v4 (src/pbrt/media.cpp, Apache-2.0), Mitsuba (src/medium/materials.h,
GPL-3: numbers only, the file itself is not in this repository) and pbrt-v2 (src/core/volume.cpp) into raw.json, for make_json.py. Run in a folder holding those three files, fetched at the
commits make_json.py names (pbrt_v4_media.cpp, mitsuba_materials.h, pbrt_v2_volume.cpp)."""
import re, json
num = r"[-+0-9.eE]+"
def rgb(s): return [float(x) for x in re.findall(num, s)]
v4 = {}
for m in re.finditer(r'\{"([^"]+)", RGB\(([^)]*)\), RGB\(([^)]*)\)\}', open("pbrt_v4_media.cpp").read()):
    v4[m.group(1)] = (rgb(m.group(2)), rgb(m.group(3)))
mi = {}
for m in re.finditer(r'\{ "([^"]+)",\s*\{([^}]*)\},\s*\{([^}]*)\},\s*\{([^}]*)\},\s*(' + num + ')f \}', open("mitsuba_materials.h").read()):
    mi[m.group(1)] = ([float(x.strip().rstrip('f')) for x in m.group(2).split(',')], [float(x.strip().rstrip('f')) for x in m.group(3).split(',')],
                      [float(x.strip().rstrip('f')) for x in m.group(4).split(',')], float(m.group(5)))
v2 = {}
for m in re.finditer(r'\{ "([^"]+)", \{([^}]*)\}, \{([^}]*)\} \}', open("pbrt_v2_volume.cpp").read()):
    v2[m.group(1)] = (rgb(m.group(2)), rgb(m.group(3)))
print(len(v4), len(mi), len(v2))
json.dump({"v4": v4, "mi": mi, "v2": v2}, open("raw.json", "w"), indent=1)
