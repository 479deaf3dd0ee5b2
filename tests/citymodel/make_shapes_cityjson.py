#!/usr/bin/env python3
# Writes shapes.city.json (CityJSON 2.0), shapes_v1_1.city.json and shapes_v1_0.city.json (plain
# float vertices) from one list of rings, so that the three hold exactly the same geometry.
# Rings: outer rings counter-clockwise seen from outside the solid, holes clockwise; each ring
# starts at its corner of least (z, x, y). Faces of a solid: bottom faces (floor first), walls
# counter-clockwise seen from above starting at the wall at min y (lower tier first), then top
# faces (roofs). Run from this folder: python3 make_shapes_cityjson.py
import json
from fractions import Fraction

X0, Y0 = 85000, 446000          # the README's offsets: objects are given relative to these
TRANSLATE = [84990.0, 445980.0, 0.0]
# x and y in millimetres; z in thirds of a millimetre, so that the terrain's heights 5/3 and 10/3
# (README: rising linearly from 0 to 5 over three 10 m squares) are whole numbers too.
SCALE = [Fraction(1, 1000), Fraction(1, 1000), Fraction(1, 3000)]


def P(x, y, z):
    return (Fraction(x) + X0, Fraction(y) + Y0, Fraction(z))


def start_least(ring):
    i = min(range(len(ring)), key=lambda k: (ring[k][2], ring[k][0], ring[k][1]))
    return ring[i:] + ring[:i]


def newell(ring):
    n = [Fraction(0)] * 3
    for a, b in zip(ring, ring[1:] + ring[:1]):
        n[0] += (a[1] - b[1]) * (a[2] + b[2])
        n[1] += (a[2] - b[2]) * (a[0] + b[0])
        n[2] += (a[0] - b[0]) * (a[1] + b[1])
    return n


def face(outer, *holes):
    return [start_least(outer)] + [start_least(h) for h in holes]


def box_faces(x0, y0, z0, x1, y1, z1, roof=True):
    f = [face([P(x0, y0, z0), P(x0, y1, z0), P(x1, y1, z0), P(x1, y0, z0)]),   # floor
         face([P(x0, y0, z0), P(x1, y0, z0), P(x1, y0, z1), P(x0, y0, z1)]),   # south (min y)
         face([P(x1, y0, z0), P(x1, y1, z0), P(x1, y1, z1), P(x1, y0, z1)]),   # east
         face([P(x1, y1, z0), P(x0, y1, z0), P(x0, y1, z1), P(x1, y1, z1)]),   # north
         face([P(x0, y1, z0), P(x0, y0, z0), P(x0, y0, z1), P(x0, y1, z1)])]   # west
    if roof:
        f.append(face([P(x0, y0, z1), P(x1, y0, z1), P(x1, y1, z1), P(x0, y1, z1)]))
    return f


def check_closed(name, faces):
    # Every directed edge once, and its reverse once: closed and consistently oriented.
    edges = {}
    for f in faces:
        for r in f:
            for a, b in zip(r, r[1:] + r[:1]):
                assert (a, b) not in edges, (name, a, b)
                edges[(a, b)] = True
    for a, b in edges:
        assert (b, a) in edges, (name, 'open edge', a, b)
    # Outward: positive volume (divergence theorem over the faces' Newell normals).
    vol = Fraction(0)
    for f in faces:
        for r in f:
            o = r[0]
            for a, b in zip(r[1:], r[2:]):
                u = [a[i] - o[i] for i in range(3)]
                v = [b[i] - o[i] for i in range(3)]
                c = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]
                vol += sum(o[i] * c[i] for i in range(3)) / 6
    assert vol > 0, (name, vol)
    return vol


def gabled():
    f = [face([P(0, 0, 0), P(0, 8, 0), P(10, 8, 0), P(10, 0, 0)]),
         face([P(0, 0, 0), P(10, 0, 0), P(10, 0, 6), P(0, 0, 6)]),
         face([P(10, 0, 0), P(10, 8, 0), P(10, 8, 6), P(10, 4, 9), P(10, 0, 6)]),
         face([P(10, 8, 0), P(0, 8, 0), P(0, 8, 6), P(10, 8, 6)]),
         face([P(0, 8, 0), P(0, 0, 0), P(0, 0, 6), P(0, 4, 9), P(0, 8, 6)]),
         face([P(0, 0, 6), P(10, 0, 6), P(10, 4, 9), P(0, 4, 9)]),
         face([P(10, 8, 6), P(0, 8, 6), P(0, 4, 9), P(10, 4, 9)])]
    assert check_closed('gabled', f) == 10 * 8 * 6 + 10 * 8 * 3 / 2
    return f


def tower():
    podium = box_faces(20, 0, 0, 40, 20, 5, roof=False)
    tw = box_faces(26, 6, 5, 34, 14, 30)
    podium_roof = face([P(20, 0, 5), P(40, 0, 5), P(40, 20, 5), P(20, 20, 5)],
                       [P(26, 6, 5), P(26, 14, 5), P(34, 14, 5), P(34, 6, 5)])
    f = podium + tw[1:5] + [podium_roof, tw[5]]
    assert check_closed('tower', f) == 20 * 20 * 5 + 8 * 8 * 25
    return f


def overhang():
    f = [face([P(70, 0, 0), P(70, 6, 0), P(80, 6, 0), P(80, 0, 0)]),                    # floor
         face([P(70, 6, 3), P(70, 10, 3), P(80, 10, 3), P(80, 6, 3)]),                  # underside
         face([P(70, 0, 0), P(80, 0, 0), P(80, 0, 6), P(70, 0, 6)]),                    # south
         face([P(80, 0, 0), P(80, 6, 0), P(80, 6, 3), P(80, 10, 3), P(80, 10, 6), P(80, 0, 6)]),
         face([P(80, 6, 0), P(70, 6, 0), P(70, 6, 3), P(80, 6, 3)]),                    # north, lower
         face([P(80, 10, 3), P(70, 10, 3), P(70, 10, 6), P(80, 10, 6)]),                # north, upper
         face([P(70, 10, 3), P(70, 6, 3), P(70, 6, 0), P(70, 0, 0), P(70, 0, 6), P(70, 10, 6)]),
         face([P(70, 0, 6), P(80, 0, 6), P(80, 10, 6), P(70, 10, 6)])]                  # roof
    assert check_closed('overhang', f) == 10 * 6 * 3 + 10 * 10 * 3
    return f


def courtyard():
    ox0, oy0, ox1, oy1, ix0, iy0, ix1, iy1 = 100, 0, 120, 20, 106, 6, 114, 14
    floor = face([P(ox0, oy0, 0), P(ox0, oy1, 0), P(ox1, oy1, 0), P(ox1, oy0, 0)],
                 [P(ix0, iy0, 0), P(ix1, iy0, 0), P(ix1, iy1, 0), P(ix0, iy1, 0)])
    outer_walls = box_faces(ox0, oy0, 0, ox1, oy1, 10)[1:5]
    # Inner walls face into the courtyard; counter-clockwise from the one at min y.
    inner_walls = [face([P(ix1, iy0, 0), P(ix0, iy0, 0), P(ix0, iy0, 10), P(ix1, iy0, 10)]),
                   face([P(ix1, iy1, 0), P(ix1, iy0, 0), P(ix1, iy0, 10), P(ix1, iy1, 10)]),
                   face([P(ix0, iy1, 0), P(ix1, iy1, 0), P(ix1, iy1, 10), P(ix0, iy1, 10)]),
                   face([P(ix0, iy0, 0), P(ix0, iy1, 0), P(ix0, iy1, 10), P(ix0, iy0, 10)])]
    roof = face([P(ox0, oy0, 10), P(ox1, oy0, 10), P(ox1, oy1, 10), P(ox0, oy1, 10)],
                [P(ix0, iy0, 10), P(ix0, iy1, 10), P(ix1, iy1, 10), P(ix1, iy0, 10)])
    f = [floor] + outer_walls + inner_walls + [roof]
    assert check_closed('courtyard', f) == (400 - 64) * 10
    return f


def closed_box(name, *a):
    f = box_faces(*a)
    check_closed(name, f)
    return f


def terrain():
    xs, ys = [130, 140, 150, 160], [-10, 0, 10, 20]
    # Height 0 at x 85130 rising linearly to 5 at x 85160: 0, 5/3, 10/3, 5.
    z = {130: Fraction(0), 140: Fraction(5, 3), 150: Fraction(10, 3), 160: Fraction(5)}
    tris = []
    for j in range(3):
        for i in range(3):
            x0, x1, y0, y1 = xs[i], xs[i + 1], ys[j], ys[j + 1]
            a, b, c, d = P(x0, y0, z[x0]), P(x1, y0, z[x1]), P(x1, y1, z[x1]), P(x0, y1, z[x0])
            tris.append(face([a, b, c]))
            tris.append(face([a, c, d]))
    for t in tris:
        assert newell(t[0])[2] > 0
    return tris


def lamp_template():
    # Local coordinates: centred on the reference point in x and y, standing on it.
    h = Fraction(1, 10)
    def L(x, y, z): return (Fraction(x), Fraction(y), Fraction(z))
    f = [[[L(-h, -h, 0), L(-h, h, 0), L(h, h, 0), L(h, -h, 0)]],
         [[L(-h, -h, 0), L(h, -h, 0), L(h, -h, 4), L(-h, -h, 4)]],
         [[L(h, -h, 0), L(h, h, 0), L(h, h, 4), L(h, -h, 4)]],
         [[L(h, h, 0), L(-h, h, 0), L(-h, h, 4), L(h, h, 4)]],
         [[L(-h, h, 0), L(-h, -h, 0), L(-h, -h, 4), L(-h, h, 4)]],
         [[L(-h, -h, 4), L(h, -h, 4), L(h, h, 4), L(-h, h, 4)]]]
    check_closed('lamp', f)
    return f


IDENTITY = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]

# (id, type, parent, children, geometry): geometry is (type, lod, faces) or ('instance', point).
OBJECTS = [
    ('gabled', 'Building', None, None, ('Solid', '2', gabled())),
    ('tower', 'Building', None, None, ('Solid', '2', tower())),
    ('stacked', 'Building', None, ['stacked-base', 'stacked-top'], None),
    ('stacked-base', 'BuildingPart', 'stacked', None, ('Solid', '2', closed_box('base', 50, 0, 0, 60, 10, 4))),
    ('stacked-top', 'BuildingPart', 'stacked', None, ('Solid', '2', closed_box('top', 50, 0, 4, 60, 10, 8))),
    ('overhang', 'Building', None, None, ('Solid', '2', overhang())),
    ('open', 'Building', None, None, ('Solid', '2', box_faces(90, 0, 0, 95, 5, 5, roof=False))),
    ('courtyard', 'Building', None, None, ('Solid', '1', courtyard())),
    ('slope', 'Building', None, None, ('Solid', '2', closed_box('slope', 140, 0, 1, 150, 10, 10))),
    ('terrain', 'TINRelief', None, None, ('CompositeSurface', '2', terrain())),
    ('lamp', 'CityFurniture', None, None, ('instance', P(125, 0, 0))),
    ('lamp2', 'CityFurniture', None, None, ('instance', P(125, 10, 0))),
    ('garden', 'LandUse', None, None, ('MultiSurface', '1', [face([P(0, 30, 0), P(10, 30, 0), P(10, 40, 0), P(0, 40, 0)])])),
    ('bridge', 'Bridge', None, None, ('Solid', '1', closed_box('bridge', 0, 50, 3, 20, 54, 4))),
]


def write(path, version, transform):
    vertices, index = [], {}

    def vi(p):
        if p not in index:
            index[p] = len(vertices)
            vertices.append(p)
        return index[p]

    def lod(text):
        if version == '1.0':
            return float(text) if '.' in text else int(text)
        return text

    def surfaces(faces):
        return [[[vi(p) for p in ring] for ring in f] for f in faces]

    city_objects = {}
    for oid, otype, parent, children, geom in OBJECTS:
        o = {'type': otype}
        if parent:
            o['parents'] = [parent]
        if children:
            o['children'] = children
        g = []
        if geom is not None and geom[0] == 'instance':
            g.append({'type': 'GeometryInstance', 'template': 0, 'boundaries': [vi(geom[1])],
                      'transformationMatrix': IDENTITY})
        elif geom is not None:
            gtype, glod, faces = geom
            b = surfaces(faces)
            g.append({'type': gtype, 'lod': lod(glod), 'boundaries': [b] if gtype == 'Solid' else b})
        o['geometry'] = g
        city_objects[oid] = o

    tverts = []
    tindex = {}
    def tvi(p):
        if p not in tindex:
            tindex[p] = len(tverts)
            tverts.append([float(c) for c in p])
        return tindex[p]
    template = {'type': 'MultiSurface', 'lod': lod('1'),
                'boundaries': [[[tvi(p) for p in ring] for ring in f] for f in lamp_template()]}

    if transform:
        def enc(p):
            q = [(p[i] - Fraction(TRANSLATE[i]).limit_denominator()) / SCALE[i] for i in range(3)]
            assert all(c.denominator == 1 for c in q), p
            return [int(c) for c in q]
    else:
        def enc(p):
            return [float(c) for c in p]
    crs = ('urn:ogc:def:crs:EPSG::28992' if version == '1.0'
           else 'https://www.opengis.net/def/crs/EPSG/0/28992')
    doc = {'type': 'CityJSON', 'version': version}
    if transform:
        doc['transform'] = {'scale': [float(c) for c in SCALE], 'translate': TRANSLATE}
    doc['metadata'] = {'referenceSystem': crs}
    doc['CityObjects'] = city_objects
    doc['vertices'] = [enc(p) for p in vertices]
    doc['geometry-templates'] = {'templates': [template], 'vertices-templates': tverts}
    with open(path, 'w') as out:
        out.write(pretty(doc))


def pretty(doc):
    # One key a line at the top, one city object a line, one vertex a line.
    lines = ['{']
    items = list(doc.items())
    for k, (key, value) in enumerate(items):
        end = ',' if k + 1 < len(items) else ''
        if key == 'CityObjects':
            lines.append(f'  "{key}": {{')
            objs = list(value.items())
            for j, (oid, o) in enumerate(objs):
                lines.append(f'    {json.dumps(oid)}: {json.dumps(o, separators=(",", ":"))}'
                             + (',' if j + 1 < len(objs) else ''))
            lines.append('  }' + end)
        elif key in ('vertices',):
            lines.append(f'  "{key}": [')
            for j, v in enumerate(value):
                lines.append('    ' + json.dumps(v) + (',' if j + 1 < len(value) else ''))
            lines.append('  ]' + end)
        else:
            lines.append(f'  "{key}": {json.dumps(value, separators=(",", ":"))}{end}')
    lines.append('}')
    return '\n'.join(lines) + '\n'


if __name__ == '__main__':
    write('shapes.city.json', '2.0', True)
    write('shapes_v1_1.city.json', '1.1', True)
    write('shapes_v1_0.city.json', '1.0', False)
