#!/usr/bin/env python3
# Writes floorless.city.json and derived_ground.city.json (CityJSON 2.0): LoD1 solids without a
# ground surface, as extruded models (the 3D BAG) give them, for the floor closing and the
# derived ground (README.md). Coordinates as in the shapes files: EPSG:28992 metres around
# (85000, 446000); rings start at their corner of least (z, x, y); outer rings counter-clockwise
# seen from outside. Run from this folder: python3 make_floorless_cityjson.py
import json
from fractions import Fraction

from make_shapes_cityjson import P, face, check_closed, pretty

TRANSLATE = [84990.0, 445980.0, 0.0]
SCALE = [Fraction(1, 1000)] * 3


def prism(outer, holes, z0, z1, floor=True, skip_walls=()):
    """A prism over `outer` (counter-clockwise from above) with `holes` (clockwise), z0..z1:
    the floor (unless floor=False), the walls (outer ring's first, the holes' after; those whose
    index is in skip_walls are left out), the roof."""
    z0, z1 = Fraction(z0), Fraction(z1)
    f = []
    if floor:
        f.append(face([P(x, y, z0) for x, y in reversed(outer)],
                      *[[P(x, y, z0) for x, y in reversed(h)] for h in holes]))
    k = 0
    for ring in [outer] + list(holes):
        for (ax, ay), (bx, by) in zip(ring, ring[1:] + ring[:1]):
            if k not in skip_walls:
                f.append(face([P(ax, ay, z0), P(bx, by, z0), P(bx, by, z1), P(ax, ay, z1)]))
            k += 1
    f.append(face([P(x, y, z1) for x, y in outer], *[[P(x, y, z1) for x, y in h] for h in holes]))
    return f


def floorless(outer, holes, z0, z1):
    # Closed with its floor, then the floor left out.
    check_closed('floorless', prism(outer, holes, z0, z1))
    return prism(outer, holes, z0, z1, floor=False)


FLOORLESS = [
    # A box 10 x 8 x 6: its floor two triangles.
    ('box', 'Building', ('Solid', '1', floorless([(0, 0), (10, 0), (10, 8), (0, 8)], [], 0, 6))),
    # An L 12 x 12 less 6 x 7, 7 high: its floor four triangles.
    ('ell', 'Building', ('Solid', '1', floorless([(20, 0), (32, 0), (32, 5), (26, 5), (26, 12), (20, 12)], [], 0, 7))),
    # A 20 x 20 block round an 8 x 8 courtyard, 10 high: two loops, the inner one a hole.
    ('ring', 'Building', ('Solid', '1', floorless([(40, 0), (60, 0), (60, 20), (40, 20)],
                                                  [[(46, 6), (46, 14), (54, 14), (54, 6)]], 0, 10))),
    # A floorless box missing its east wall as well: open up the wall's edges, not a floor.
    ('no-wall', 'Building', ('Solid', '1', prism([(70, 0), (80, 0), (80, 8), (70, 8)], [], 0, 6,
                                                 floor=False, skip_walls=(1,)))),
]

# A road rising 3 m over 60 m (z = x / 20) with two floorless buildings standing on it, their
# floors flat: 'low' at 0.7 m (the road under it 0.5 to 1.0 m), 'high' at 2 m (1.75 to 2.25 m).
DERIVED = [
    ('road', 'Road', ('MultiSurface', '1', [face([P(0, 0, 0), P(60, 0, 3), P(60, 20, 3), P(0, 20, 0)])])),
    ('low', 'Building', ('Solid', '1', floorless([(10, 5), (20, 5), (20, 15), (10, 15)], [], Fraction(7, 10),
                                                 Fraction(87, 10)))),
    ('high', 'Building', ('Solid', '1', floorless([(35, 5), (45, 5), (45, 15), (35, 15)], [], 2, 12))),
]


def write(path, objects):
    vertices, index = [], {}

    def vi(p):
        if p not in index:
            index[p] = len(vertices)
            vertices.append(p)
        return index[p]

    city_objects = {}
    for oid, otype, (gtype, glod, faces) in objects:
        b = [[[vi(p) for p in ring] for ring in f] for f in faces]
        city_objects[oid] = {'type': otype,
                             'geometry': [{'type': gtype, 'lod': glod, 'boundaries': [b] if gtype == 'Solid' else b}]}

    def enc(p):
        q = [(p[i] - Fraction(TRANSLATE[i])) / SCALE[i] for i in range(3)]
        assert all(c.denominator == 1 for c in q), p
        return [int(c) for c in q]
    doc = {'type': 'CityJSON', 'version': '2.0',
           'transform': {'scale': [float(c) for c in SCALE], 'translate': TRANSLATE},
           'metadata': {'referenceSystem': 'https://www.opengis.net/def/crs/EPSG/0/28992'},
           'CityObjects': city_objects,
           'vertices': [enc(p) for p in vertices]}
    with open(path, 'w') as out:
        out.write(pretty(doc))


if __name__ == '__main__':
    write('floorless.city.json', FLOORLESS)
    write('derived_ground.city.json', DERIVED)
