"""Writes ``examples/head/head.obj`` from the Lee Perry-Smith head scan (the recipe; the output is committed).

Source: "Infinite, 3D Head Scan" by Lee Perry-Smith (Infinite-Realities, www.ir-ltd.net), based on
a work at www.triplegangers.com, CC BY 3.0 Unported; the closed, UV-mapped ``head.OBJ`` of Morgan
McGuire's Computer Graphics Archive (as redistributed in github.com/jknuuttila/svbrdf-oculus,
``bin/data/head``). ``examples/head/LICENSE.txt`` carries the attribution.

What changes (CC BY 3.0 allows adaptations; these are ours):

* axes: the scan's +y (up) becomes +z, jsss's and the environment map's up, and its face, which
  looks along +z, looks along -y: ``(x, y, z) -> (x, -z, y)``; lengths stay in the file's
  units (metres, give ``units = "m"``);
* vertices that ZBrush wrote once per face corner are welded (the scan is then one closed,
  consistently wound surface), texture coordinates are deduplicated, and numbers are written to
  six decimals (a micrometre) to keep the file small;
* the material library line goes: its colour photograph is not redistributed here; the example
  makes its own colour map (``examples/head/make_skin_map.py``).

Run: ``python scripts/convert_head.py path/to/head.OBJ examples/head/head.obj``.
"""

import sys

import numpy as np


def read_obj(path):
    """Positions, texture coordinates and faces (corner index pairs) of a plain OBJ."""
    positions, uvs, faces = [], [], []
    with open(path, encoding="ascii", errors="strict") as f:
        for line in f:
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "v":
                positions.append([float(x) for x in parts[1:4]])
            elif parts[0] == "vt":
                uvs.append([float(x) for x in parts[1:3]])
            elif parts[0] == "f":
                corners = [corner.split("/") for corner in parts[1:]]
                faces.append([(int(c[0]) - 1, int(c[1]) - 1) for c in corners])
    return np.asarray(positions), np.asarray(uvs), faces


def main(source, target):
    positions, uvs, faces = read_obj(source)
    # Weld positions that ZBrush repeated (exact duplicates), and texture coordinates to 1e-6.
    welded, position_index = np.unique(np.round(positions, 7), axis=0, return_inverse=True)
    uv_rounded = np.round(uvs, 6)
    uv_unique, uv_index = np.unique(uv_rounded, axis=0, return_inverse=True)
    position_index, uv_index = position_index.ravel(), uv_index.ravel()
    turned = np.stack([welded[:, 0], -welded[:, 2], welded[:, 1]], axis=1)  # y up -> z up, face -> -y
    with open(target, "w", encoding="ascii", newline="\n") as out:
        out.write("# Infinite, 3D Head Scan by Lee Perry-Smith (Infinite-Realities, www.ir-ltd.net),\n"
                  "# based on a work at www.triplegangers.com; CC BY 3.0 Unported (see LICENSE.txt here).\n"
                  "# Adapted for jsss by scripts/convert_head.py: turned to +z up (face toward -y), welded,\n"
                  "# texture coordinates deduplicated, six decimals. Units: metres.\n")
        out.writelines(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in turned)
        out.writelines(f"vt {u:.6f} {v:.6f}\n" for u, v in uv_unique)
        out.writelines("f " + " ".join(f"{position_index[p] + 1}/{uv_index[t] + 1}" for p, t in face) + "\n"
                       for face in faces)
    print(f"{target}: {len(turned)} vertices, {len(uv_unique)} texture coordinates, {len(faces)} faces")


if __name__ == "__main__":
    main(*sys.argv[1:3])
