// Setup in lanes (HEMIRAD_SETUP_LANES, CPUs): HR_SETUP_LANES elements per work-item from the
// structure-of-arrays copy HrElementLanes. Included by hemicube_setup.cl after setup_element,
// which it falls back on; empty without HEMIRAD_SETUP_LANES.

#if HEMIRAD_SETUP_LANES
// setup_lanes: HR_SETUP_LANES elements per work-item, each lane an element, in the operations
// (and order) of setup_element. The common case takes no branch per element: an element
// wholly inside one face's frustum and hidden on the other four (by the rule setup_element
// follows: the first plane any vertex is outside of has every vertex outside) needs no
// clipping. The other lanes go through setup_element.
typedef double8 ldouble;
typedef long8 llong;

// Where face == f (per lane), these values, as to_face permutes and negates.
void to_face_lanes(llong face, ldouble x, ldouble y, ldouble z, ldouble* u, ldouble* v, ldouble* d) {
    *u = select(select(select(select(x, -x, face == 3), -y, face == 2), y, face == 1), x, face == 0);
    *v = select(z, y, face == 0);
    *d = select(select(select(select(-y, y, face == 3), -x, face == 2), x, face == 1), z, face == 0);
}

// outside_bits, a lane per element, where a plane value is < -margin (outside_bits: margin 0).
llong outside_bits_lanes(ldouble x, ldouble y, ldouble z, double eps, ldouble margin) {
    const ldouble low = -margin;
    const llong base = (z - eps < low) & 1;
    const ldouble zmx = z - x, zpx = z + x, zmy = z - y, zpy = z + y, xmy = x - y, xpy = x + y;
    const llong face0 = base | ((zmx < low) & 2) | ((zpx < low) & 4) | ((zmy < low) & 8) | ((zpy < low) & 16);
    const llong face1 = base | ((xmy < low) & 2) | ((xpy < low) & 4) | ((zmx > margin) & 8);
    const llong face2 = base | ((xmy > margin) & 2) | ((xpy > margin) & 4) | ((zpx > margin) & 8);
    const llong face3 = base | ((xpy < low) & 2) | ((xmy > margin) & 4) | ((zmy > margin) & 8);
    const llong face4 = base | ((xpy > margin) & 2) | ((xmy < low) & 4) | ((zpy > margin) & 8);
    return face0 | face1 << 5 | face2 << 10 | face3 << 15 | face4 << 20;
}

// floor_div (below) a lane at a time, for |m| < 2^53 and inverse ~ 1 / d: the estimate m
// inverse truncated, then corrected until every remainder is in [0, d).
llong floor_div_lanes(llong m, llong d, ldouble inverse, llong* rem) {
    llong q = convert_long8_rtz(convert_double8(m) * inverse);
    llong r = m - q * d;
    while (any_of8(r < 0)) {
        const llong under = r < 0;  // -1 in such lanes
        q += under;
        r += d & under;
    }
    while (any_of8(r >= d)) {
        const llong over = r >= d;
        q -= over;
        r -= d & over;
    }
    *rem = r;
    return q;
}

llong abs_lanes(llong v) {
    return select(v, -v, v < 0);
}

llong snap_lanes(ldouble cells) {
    return convert_long8(floor(cells * (double)SUBCELL + 0.5));
}

void setup_lanes(const HrShot* shot, __global const HrElementLanes* group, int first,
                 __global HrRecord* records, __global HrBox* boxes,
                 __local uint* used) {
    const double eps = shot->eps;
    const llong n_lanes = convert_long8(vload8(0, group->n));
    const int8 patch = vload8(0, group->patch);
    const llong mine = convert_long8(patch == (int8)(shot->shooter) || patch == (int8)(shot->twin));
    const llong has_twin = convert_long8(vload8(0, group->has_twin) != 0);
    const ldouble normal_x = vload8(0, group->normal), normal_y = vload8(1, group->normal),
                  normal_z = vload8(2, group->normal);
    const ldouble facing = normal_x * (shot->origin[0] - vload8(0, group->centroid)) +
                           normal_y * (shot->origin[1] - vload8(1, group->centroid)) +
                           normal_z * (shot->origin[2] - vload8(2, group->centroid));
    const llong is_back = facing < 0.0;
    llong live = (n_lanes > 0) & ~mine & ~(is_back & has_twin);
    // A group of backs whose twins face the shooter (the mesh keeps fronts and backs apart, so
    // from any point such groups are common), or of the shooter's own: nothing to set up.
    if (!any_of8(live)) return;

    // to_local, four vertices (a triangle's last repeated: the same values, the same bits).
    ldouble lx[4], ly[4], lz[4];
    llong above = 0, outside_all = -1, outside_any = 0;
    ldouble magnitude = eps;  // of every coordinate and eps
    for (int i = 0; i < 4; ++i) {
        const ldouble dx = vload8(3 * i, group->v) - shot->origin[0];
        const ldouble dy = vload8(3 * i + 1, group->v) - shot->origin[1];
        const ldouble dz = vload8(3 * i + 2, group->v) - shot->origin[2];
        lx[i] = dx * shot->u[0] + dy * shot->u[1] + dz * shot->u[2];
        ly[i] = dx * shot->v[0] + dy * shot->v[1] + dz * shot->v[2];
        lz[i] = dx * shot->w[0] + dy * shot->w[1] + dz * shot->w[2];
        above |= lz[i] > eps;
        const llong bits = outside_bits_lanes(lx[i], ly[i], lz[i], eps, 0.0);
        outside_all &= bits;
        outside_any |= bits;
        magnitude = fmax(magnitude, fmax(fabs(lx[i]), fmax(fabs(ly[i]), fabs(lz[i]))));
    }
    live &= above;
    if (!any_of8(live)) return;  // all behind the base plane (or the shooter's): no record
    // The one face with no vertex outside, every other hidden: the first of its planes any
    // vertex is outside of (lowest bit) has all outside, or one has all outside by the margin
    // (HIDDEN_MARGIN). The margin's test only for lanes the first leaves in doubt (elements
    // across a face's diagonal, mostly), and only where a lane of the group has such a face.
    llong face = -1, fast = live, settled = 0, doubt = 0;  // settled: bit f, face f needs no margin
    for (int f = 0; f < HR_FACES; ++f) {
        const long planes = f == 0 ? 0x1f : 0x0f;
        const llong any_out = (outside_any >> (5 * f)) & planes, all_out = (outside_all >> (5 * f)) & planes;
        const llong inside = any_out == 0;
        fast &= ~(inside & (face >= 0));  // two such faces: leave it to setup_element
        face = select(face, (llong)(f), inside);
        const llong ok = inside | ((any_out & -any_out & all_out) != 0);
        settled |= ok & (1L << f);
        doubt |= ~ok;
    }
    fast &= face >= 0;
    if (any_of8(fast & doubt)) {
        const ldouble margin = magnitude * HIDDEN_MARGIN;
        llong deep_all = -1;  // planes every vertex is outside of by the margin
        for (int i = 0; i < 4; ++i) deep_all &= outside_bits_lanes(lx[i], ly[i], lz[i], eps, margin);
        for (int f = 0; f < HR_FACES; ++f) {
            const long planes = f == 0 ? 0x1f : 0x0f;
            fast &= ((settled & (1L << f)) != 0) | (((deep_all >> (5 * f)) & planes) != 0);
        }
    }

    const ldouble normal_u = normal_x * shot->u[0] + normal_y * shot->u[1] + normal_z * shot->u[2];
    const ldouble normal_v = normal_x * shot->v[0] + normal_y * shot->v[1] + normal_z * shot->v[2];
    const ldouble normal_w = normal_x * shot->w[0] + normal_y * shot->w[1] + normal_z * shot->w[2];
    ldouble nu, nv, nd;
    to_face_lanes(face, normal_u, normal_v, normal_w, &nu, &nv, &nd);
    const double per_unit = 0.5 * shot->n;
    const ldouble t0 = select((ldouble)(0.0), (ldouble)(1.0), face == 0);
    llong px[4], py[4];
    ldouble c = 0.0;
    for (int i = 0; i < 4; ++i) {
        ldouble u, v, d;
        to_face_lanes(face, lx[i], ly[i], lz[i], &u, &v, &d);
        if (i == 0) c = nu * u + nv * v + nd * d;
        px[i] = snap_lanes((u / d + 1.0) * per_unit);
        py[i] = snap_lanes((v / d + t0) * per_unit);
    }
    llong record = fast & (fabs(c) > eps * 1e-3);  // else seen edge-on: covers no area
    llong area2 = 0;
    for (int i = 0; i < 4; ++i) area2 += px[i] * py[(i + 1) & 3] - px[(i + 1) & 3] * py[i];
    record &= area2 != 0;
    const llong reverse = area2 < 0;  // make counter-clockwise
    llong x[4], y[4];
    llong xmin = px[0], xmax = px[0], ymin = py[0], ymax = py[0];
    for (int i = 0; i < 4; ++i) {
        x[i] = select(px[i], px[3 - i], reverse);
        y[i] = select(py[i], py[3 - i], reverse);
        xmin = min(xmin, px[i]);
        xmax = max(xmax, px[i]);
        ymin = min(ymin, py[i]);
        ymax = max(ymax, py[i]);
    }
    const double sub = (double)SUBCELL;
    const llong rows = select((llong)(shot->n / 2), (llong)(shot->n), face == 0);
    const llong i0 = max((llong)(0), convert_long8(ceil(convert_double8(xmin - SUBCELL / 2) / sub)));
    const llong i1 = min((llong)(shot->n - 1), convert_long8(floor(convert_double8(xmax - SUBCELL / 2) / sub)));
    const llong j0 = max((llong)(0), convert_long8(ceil(convert_double8(ymin - SUBCELL / 2) / sub)));
    const llong j1 = min(rows - 1, convert_long8(floor(convert_double8(ymax - SUBCELL / 2) / sub)));
    record &= (i0 <= i1) & (j0 <= j1);
    // No record and nothing for setup_element: common where elements are smaller than a cell.
    if (!any_of8(record | (live & ~fast))) return;

    // The edges of the inside test, as setup_element makes them; and in lanes, divided through
    // by SUBCELL = S (a and b are multiples of it, and for integers a' i + b' j, a i + b j + c > 0
    // is a' i + b' j > -c / S, is a' i + b' j + ceil(c / S) > 0), which keeps the quotients
    // below in doubles' exact range (|m| < 2^42 up to N = 4096).
    // Per lane from here, through private copies (portable OpenCL C indexes no vector).
    long a_lane[4][HR_SETUP_LANES], b_lane[4][HR_SETUP_LANES], c_lane[4][HR_SETUP_LANES];
    llong edge_a[4], edge_b[4], edge_c[4];
    for (int e = 0; e < 4; ++e) {
        const int f = (e + 1) & 3;
        const llong dx = x[f] - x[e], dy = y[f] - y[e];
        const llong owns = (dy < 0) | ((dy == 0) & (dx > 0));  // owns_edge_point
        const long half_cell = SUBCELL / 2;
        const llong c_full = dx * (half_cell - y[e]) - dy * (half_cell - x[e]) + (owns & 1);
        // A repeated vertex (a triangle's, or one snapping made) gives no edge: a = b = 0 marks it.
        vstore8(-dy * SUBCELL, 0, a_lane[e]);
        vstore8(dx * SUBCELL, 0, b_lane[e]);
        vstore8(c_full, 0, c_lane[e]);
        // Zero in lanes without a record, whose values may be anything (an element behind the
        // shooter projects to infinities): the divisions below must end.
        edge_a[e] = select((llong)(0), -dy, record);
        edge_b[e] = select((llong)(0), dx, record);
        const llong minus_c = -c_full;  // ceil(c / S) = -floor(-c / S), the floor exact in integers
        edge_c[e] = select((llong)(0), -((minus_c - (minus_c & (SUBCELL - 1))) / SUBCELL), record);
    }

    // Spans, for records of at most HR_SPAN_ROWS rows: the raster's row bounds (see
    // raster_records), worked out here for a lane of elements at once. Horizontal edges bound
    // the rows; on each row, left edges (a > 0) the first cell and right edges (a < 0) the last,
    // exact quotients stepped from row to row.
    llong row0 = j0, row1 = j1;
    for (int e = 0; e < 4; ++e) {
        const llong flat = (edge_a[e] == 0) & (edge_b[e] != 0);
        if (!any_of8(flat)) continue;
        llong rem;
        const llong d = select((llong)(1), abs_lanes(edge_b[e]), flat);
        const llong q = floor_div_lanes(select((llong)(0), -edge_c[e], flat), d, 1.0 / convert_double8(d), &rem);
        row0 = select(row0, max(row0, q + 1), flat & (edge_b[e] > 0));
        row1 = select(row1, min(row1, -q - 1), flat & (edge_b[e] < 0));
    }
    const llong span_rows = row1 - row0 + 1;
    const llong spans = record & (span_rows <= HR_SPAN_ROWS);
    llong edge_q[4], edge_r[4], edge_d[4], edge_sq[4], edge_sr[4];
    for (int e = 0; e < 4; ++e) {
        edge_d[e] = select((llong)(1), abs_lanes(edge_a[e]), edge_a[e] != 0);
        const ldouble inverse = 1.0 / convert_double8(edge_d[e]);
        edge_sq[e] = floor_div_lanes(edge_b[e], edge_d[e], inverse, &edge_sr[e]);
        edge_q[e] = floor_div_lanes(-(edge_b[e] * row0 + edge_c[e]), edge_d[e], inverse, &edge_r[e]);
    }
    long rows_most = 0;
    {
        long rows_lane[HR_SETUP_LANES];
        vstore8(select((llong)(0), span_rows, spans), 0, rows_lane);
        for (int l = 0; l < HR_SETUP_LANES; ++l) rows_most = max(rows_most, rows_lane[l]);
    }
    int span[HR_SPAN_ROWS][HR_SETUP_LANES];
    llong span_i0 = (llong)(1 << 30), span_i1 = -1;  // the columns the spans reach
    for (int row = 0; row < (int)rows_most; ++row) {
        llong lo = i0, hi = i1;
        for (int e = 0; e < 4; ++e) {
            lo = select(lo, max(lo, edge_q[e] + 1), edge_a[e] > 0);
            hi = select(hi, min(hi, -edge_q[e] - 1), edge_a[e] < 0);
            step_row(&edge_q[e], &edge_r[e], edge_d[e], edge_sq[e], edge_sr[e]);
        }
        const llong cells = ((llong)(row) < span_rows) & (lo <= hi);
        span_i0 = select(span_i0, min(span_i0, lo), cells);
        span_i1 = select(span_i1, max(span_i1, hi), cells);
        vstore8(convert_int8(select((llong)(HR_SPAN_NONE), lo | hi << 16, cells)), 0, span[row]);
    }
    record &= ~spans | (span_i0 <= span_i1);  // spans covering no cell centre: no record
    double plane[3][HR_SETUP_LANES];
    vstore8(nu / c, 0, plane[0]);
    vstore8(nv / c, 0, plane[1]);
    vstore8(nd / c, 0, plane[2]);
    long flags[5][HR_SETUP_LANES];  // live, fast, record, face, back
    vstore8(live, 0, flags[0]);
    vstore8(fast, 0, flags[1]);
    vstore8(record, 0, flags[2]);
    vstore8(face, 0, flags[3]);
    vstore8(is_back, 0, flags[4]);
    long box_lane[5][HR_SETUP_LANES];  // i0, i1, j0, j1; spans: 1 for a span record
    vstore8(select(i0, span_i0, spans), 0, box_lane[0]);
    vstore8(select(i1, span_i1, spans), 0, box_lane[1]);
    vstore8(select(j0, row0, spans), 0, box_lane[2]);
    vstore8(select(j1, row1, spans), 0, box_lane[3]);
    vstore8(spans & 1, 0, box_lane[4]);

    // One atomic for the records of all fast lanes: on CPUs an atomic waits for the stores
    // before it, so one per record would cost more than the record.
    uint fast_records = 0;
    for (int l = 0; l < HR_SETUP_LANES; ++l) fast_records += flags[2][l] != 0;
    uint slot = fast_records > 0 ? atomic_add(used, fast_records) : 0u;
    const uint end = region_end(shot);
    for (int l = 0; l < HR_SETUP_LANES; ++l) {
        const int k = first + l;
        if (!flags[0][l]) continue;
        if (!flags[1][l]) {
            const Element element = element_in_lanes(group, l);
            setup_element(shot, &element, k, records, boxes, used);
            continue;
        }
        if (!flags[2][l]) continue;
        if (slot >= end) continue;  // the region is full: counted only (later slots are past it too)
        __global HrRecord* r = records + slot;
        int edges = 0;
        if (box_lane[4][l]) {
            const int rows = (int)(box_lane[3][l] - box_lane[2][l]) + 1;
            for (int row = 0; row < rows; ++row) r->cover.span[row] = span[row][l];
        } else {
            for (int e = 0; e < 4; ++e) {
                if (a_lane[e][l] == 0 && b_lane[e][l] == 0) continue;
                __global HrEdge* edge = &r->cover.edge[edges++];
                edge->a = a_lane[e][l];
                edge->b = b_lane[e][l];
                edge->c = c_lane[e][l];
            }
        }
        store_record_fields(r, boxes + slot, plane[0][l], plane[1][l], plane[2][l], k, flags[4][l] != 0, edges,
                            (int)box_lane[4][l], (int)box_lane[0][l], (int)box_lane[1][l], (int)box_lane[2][l],
                            (int)box_lane[3][l], (int)flags[3][l]);
        ++slot;
    }
}
#endif
