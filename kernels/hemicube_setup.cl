// Stage 1, setup (included by hemicube.cl): cull, clip and project each element on each face
// into packed records with their cell boxes, then count them per tile. setup_element is the
// scalar path, an element at a time (a work-item per element on GPUs, and the lanes path's
// exceptions); hemicube_setup_lanes.cl the CPU path in double8 lanes and hemicube_cull.cl its
// occlusion culling, both compiled only with HEMIRAD_SETUP_LANES; then the counting shared with
// scatter (bin_records) and the setup kernel.

// Element k's records, and their cell boxes, for each face on which it may cover a cell centre,
// packed in its work-group's region of the record slots: at records[*used], *used counting up.
void setup_element(const HrShot* shot, const Element* e, int k, __global HrRecord* records,
                   __global HrBox* boxes, __local uint* used) {
    const double eps = shot->eps;
    const Vec normal = e->normal;
    const Vec origin = vec(shot->origin[0], shot->origin[1], shot->origin[2]);
    const double facing =
        dot3(normal, vec(origin.x - e->centroid.x, origin.y - e->centroid.y, origin.z - e->centroid.z));
    const int is_back = facing < 0.0;
    if (is_back && e->has_twin) return;  // the twin draws this surface from this side

    Vec in_frame[4];
    bool above = false;
    for (int i = 0; i < e->n; ++i) {
        in_frame[i] = to_local(shot, e->v[i]);
        above = above || in_frame[i].z > eps;
    }
    if (!above) return;
    const Vec normal_local = vec(dot3(normal, vec(shot->u[0], shot->u[1], shot->u[2])),
                                 dot3(normal, vec(shot->v[0], shot->v[1], shot->v[2])),
                                 dot3(normal, vec(shot->w[0], shot->w[1], shot->w[2])));
    const int n = shot->n;
    const double per_unit = 0.5 * n;  // cells per unit of face coordinate (the reference's `half`)

    // Which vertices lie outside which face planes, from the seven plane values every face
    // shares; and the planes every vertex is outside of by the margin (HIDDEN_MARGIN).
    double magnitude = eps;
    for (int i = 0; i < e->n; ++i)
        magnitude = fmax(magnitude, fmax(fabs(in_frame[i].x), fmax(fabs(in_frame[i].y), fabs(in_frame[i].z))));
    uint outside_all = ~0u, outside_any = 0u, deep_all = ~0u;
    for (int i = 0; i < e->n; ++i) {
        const uint bits = outside_bits(in_frame[i], eps, 0.0);
        outside_all &= bits;
        outside_any |= bits;
        deep_all &= outside_bits(in_frame[i], eps, magnitude * HIDDEN_MARGIN);
    }

    for (int face = 0; face < HR_FACES; ++face) {
        // Planes in the clipping order: while no plane has cut the polygon it is the element
        // itself, so a plane with every vertex in changes nothing and one with every vertex out
        // hides the face, as clip_if_needed would decide. From the first plane that cuts it on,
        // the clipping itself.
        const int planes = face == 0 ? 5 : 4;
        if ((deep_all >> (5 * face)) & ((1u << planes) - 1)) continue;  // hidden (HIDDEN_MARGIN)
        int first_cut = planes;
        bool hidden = false;
        for (int plane = 0; plane < planes && first_cut == planes && !hidden; ++plane) {
            const uint bit = 1u << (face * 5 + plane);
            hidden = (outside_all & bit) != 0;
            if (!hidden && (outside_any & bit) != 0) first_cut = plane;
        }
        if (hidden) continue;
        ClipPolygon poly;
        poly.n = 0;
        for (int i = 0; i < e->n; ++i) poly.v[poly.n++] = to_face(face, in_frame[i]);
        bool visible = true;
        for (int plane = first_cut; plane < planes && visible; ++plane)
            visible = clip_if_needed(&poly, plane, face, eps);
        if (!visible) continue;

        // The plane n.p = c in face coordinates gives 1/depth = (n_u s + n_v t + n_d) / c, stored
        // divided through (the reference's `plane`).
        const Vec nf = to_face(face, normal_local);
        const double c = dot3(nf, poly.v[0]);
        if (fabs(c) <= eps * 1e-3) continue;  // seen edge-on: covers no area

        // Cell coordinates, x in [0, n) and y in [0, rows), snapped to fixed point (the
        // reference's snap): from here on the inside test is exact integer arithmetic.
        const double t0 = face == 0 ? 1.0 : 0.0;
        long px[HR_MAX_CLIPPED], py[HR_MAX_CLIPPED];
        for (int i = 0; i < poly.n; ++i) {
            px[i] = snap((poly.v[i].x / poly.v[i].z + 1.0) * per_unit);
            py[i] = snap((poly.v[i].y / poly.v[i].z + t0) * per_unit);
        }
        long area2 = 0;
        for (int i = 0; i < poly.n; ++i) {
            const int j = (i + 1) % poly.n;
            area2 += px[i] * py[j] - px[j] * py[i];
        }
        if (area2 == 0) continue;
        const bool reverse = area2 < 0;  // make counter-clockwise
        long x[HR_MAX_CLIPPED], y[HR_MAX_CLIPPED];
        long xmin = px[0], xmax = px[0], ymin = py[0], ymax = py[0];
        for (int i = 0; i < poly.n; ++i) {
            const int from = reverse ? poly.n - 1 - i : i;
            x[i] = px[from];
            y[i] = py[from];
            xmin = min(xmin, px[i]);
            xmax = max(xmax, px[i]);
            ymin = min(ymin, py[i]);
            ymax = max(ymax, py[i]);
        }
        const int rows = face_rows(face, n);
        const int i0 = max(0, first_centre(xmin)), i1 = min(n - 1, last_centre(xmax));
        const int j0 = max(0, first_centre(ymin)), j1 = min(rows - 1, last_centre(ymax));
        if (i0 > i1 || j0 > j1) continue;  // no cell centre on the face: no record

        // The next slot of the work-group's region: a counter no other core touches, and the
        // records stay packed, so the raster reads little memory. Their order may vary from
        // run to run; the raster's result does not depend on it.
        const uint slot = atomic_inc(used);
        if (slot >= region_end(shot)) continue;  // the region is full: counted only
        __global HrRecord* r = records + slot;
        // The edges of the inside test: the reference's dx * (Y - ay) - dy * (X - ax) at the
        // centre X = S i + S/2, Y = S j + S/2 (S = SUBCELL), as a i + b j + c, plus 1 for an
        // edge the top-left rule gives its centres (integers: value >= 0 there is value + 1 > 0).
        const long half_cell = SUBCELL / 2;
        int edges = 0;
        for (int e = 0; e < poly.n; ++e) {
            const int f = e + 1 == poly.n ? 0 : e + 1;
            const long dx = x[f] - x[e], dy = y[f] - y[e];
            if (dx == 0 && dy == 0) continue;  // clipping or snapping can repeat a vertex
            __global HrEdge* edge = &r->cover.edge[edges++];
            edge->a = -dy * SUBCELL;
            edge->b = dx * SUBCELL;
            edge->c = dx * (half_cell - y[e]) - dy * (half_cell - x[e]) + (owns_edge_point(dx, dy) ? 1 : 0);
        }
        store_record_fields(r, boxes + slot, nf.x / c, nf.y / c, nf.z / c, k, is_back, edges, 0, i0, i1, j0, j1, face);
    }
}

#include "hemicube_setup_lanes.cl"  // setup_lanes (HEMIRAD_SETUP_LANES: the file holds its own #if)
#include "hemicube_cull.cl"         // its culling and cull_clusters (HEMIRAD_SETUP_LANES too)

// The record slots of work-group g of setup (and of scatter): lanes setup, a region of
// group_capacity; otherwise five per element it sets up (an element makes a record per face at
// most), from five times its first element.
uint group_first_slot(const HrShot* shot, int g) {
#if HEMIRAD_SETUP_LANES
    return (uint)g * shot->group_capacity;
#else
    return (uint)(HR_FACES * g * HEMIRAD_WG);
#endif
}

// setup and scatter: for each of the `used` records of setup's work-group g (this
// work-group's), an atomic increment of the counter of every tile its box touches, in the
// work-group's counter copy; with lists, the counter is a cursor and the record's index goes
// into the list at it.
void bin_records(const HrShot* shot, __global const HrBox* boxes, uint used,
                 __global uint* counters, __global uint* lists) {
    __global uint* copy = counters + counter_copy(shot->tile_base[HR_FACES]);
    const uint first = group_first_slot(shot, (int)get_group_id(0));
    used = min(used, region_end(shot) - first);  // a full region's stored records (the host reruns the shot)
    for (uint slot = first + get_local_id(0); slot < first + used; slot += HEMIRAD_WG) {
        const HrBox box = boxes[slot];
        __global uint* face_counters = copy + shot->tile_base[box.face];
        for (int ty = box.j0 / HEMIRAD_TILE; ty <= box.j1 / HEMIRAD_TILE; ++ty)
            for (int tx = box.i0 / HEMIRAD_TILE; tx <= box.i1 / HEMIRAD_TILE; ++tx) {
                const uint at = atomic_inc(&face_counters[ty * shot->tiles_x + tx]);
                if (lists != 0 && at < shot->list_capacity) lists[at] = slot;
            }
    }
}

// One work-item per element (setup_element; nothing when its patch is the shooter's or lies
// below the base plane), so that a shot is as many work-items as elements, not a few hundred
// patches each walking its elements in turn; or, with SETUP_LANES, per HR_SETUP_LANES elements
// (setup_lanes); the records packed per work-group: group_records[g] says how many the region
// of group g holds; each record then counted into the tiles it may cover (scan left the counts
// at zero). Also zeroes the sums for the raster.
__kernel __attribute__((reqd_work_group_size(HEMIRAD_WG, 1, 1))) void setup(
    const HrShot first_shot, __global const HrShot* more_shots, __global const HrElement* elements,
    __global const HrElementLanes* element_lanes, __global const HrPatch* patches, __global HrRecord* records,
    __global HrBox* boxes, __global uint* group_records, __global uint* tile_counts, __global long* sums,
    __global const int* clusters, __global const double* block_depth, const int occluded) {
    const size_t b = get_global_id(1);
    const HrShot shot_value = batch_shot(first_shot, more_shots, b);
    const HrShot* shot = &shot_value;
    records += b * record_stride(shot);
    boxes += b * record_stride(shot);
    group_records += b * group_stride(shot);
    tile_counts += b * counter_stride(shot);
    sums += b * sum_stride(shot);
    __local uint used;
#if HEMIRAD_SETUP_LANES
    // Work-group g sets up cluster clusters[b][g] (HEMIRAD_WG lane groups; -1: none), those the
    // host found not wholly behind the shot's base plane: the rest of the scene costs nothing
    // here. The host reads back only these clusters' sums, so only theirs are cleared (ahead of
    // the raster in the queue; scan leaves the tile counts at zero), and the blocked share.
    // -2 - c: cluster c, which the occluder pass set up as work-group g already: its records and
    // their count stand, and are only counted into the tiles again.
    const int entry = clusters[b * get_num_groups(0) + get_group_id(0)];
    const bool kept = entry < -1;
    const int cluster = kept ? -2 - entry : entry;
    if (get_local_id(0) == 0)
        used = group_first_slot(shot, (int)get_group_id(0)) + (kept ? group_records[get_group_id(0)] : 0u);
    barrier(CLK_LOCAL_MEM_FENCE);
    const int p = cluster * HEMIRAD_WG + (int)get_local_id(0);
    if (get_global_id(0) == 0) sums[shot->elements] = 0;
    if (get_global_id(0) == 0 && !occluded) sums[shot->elements + 2] = sums[shot->elements + 3] = 0;  // none counted here
    if (cluster >= 0)
        for (int l = 0; l < HR_SETUP_LANES && p * HR_SETUP_LANES + l < shot->elements; ++l)
            sums[p * HR_SETUP_LANES + l] = 0;
    // occluded: the occluder pass has drawn this shot's depth blocks, and the host launched only
    // the clusters cull_clusters did not hide whole; each lane group is tested (group_hidden). The
    // groups tested and those hidden are counted for benchmarks, once per work-group.
    __local uint tested, hidden;
    if (get_local_id(0) == 0) tested = hidden = 0;
    const bool in_range = !kept && cluster >= 0 && p * HR_SETUP_LANES < shot->elements;
#if HEMIRAD_CULL  // (not `HEMIRAD_CULL && …`: a constant operand draws a compiler warning on every build)
    const bool live_group = in_range && !group_behind(shot, element_lanes + p);
#else
    const bool live_group = in_range;
#endif
    barrier(CLK_LOCAL_MEM_FENCE);
    if (live_group) {
        bool drop = false;
        if (occluded) {
            drop = group_hidden(shot, element_lanes + p, block_depth + b * depth_stride(shot->n));
            atomic_inc(&tested);
            if (drop) atomic_inc(&hidden);
        }
        if (!drop) setup_lanes(shot, element_lanes + p, p * HR_SETUP_LANES, records, boxes, &used);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    if (get_local_id(0) == 0 && tested > 0) {
        atom_add(&sums[shot->elements + 2], (long)tested);
        atom_add(&sums[shot->elements + 3], (long)hidden);
    }
#else
    if (get_local_id(0) == 0) used = group_first_slot(shot, (int)get_group_id(0));
    barrier(CLK_LOCAL_MEM_FENCE);
    const int k = (int)get_global_id(0);
    // The sums' clear, ahead of the raster in the queue (scan leaves the tile counts at zero).
    for (int c = k; c <= shot->elements; c += (int)get_global_size(0)) sums[c] = 0;
    const int p = k < shot->elements ? elements[k].patch : -1;
    if (p >= 0 && p != shot->shooter && p != shot->twin) {  // the shooter's own surface, either side
        // Elements tile their patch: when the patch is below the base plane, so are they (the
        // reference skips them by this test). A cluster (n = 0) has no polygon to tell.
        __global const HrPatch* patch = patches + p;
        bool patch_above = patch->n == 0;
        for (int i = 0; i < patch->n; ++i)
            patch_above = patch_above || to_local(shot, vec(patch->v[3 * i], patch->v[3 * i + 1], patch->v[3 * i + 2]))
                                                 .z > shot->eps;
        if (patch_above) {
            const Element element = element_at(elements + k);
            setup_element(shot, &element, k, records, boxes, &used);
        }
    }
#endif
    // The work-group's records complete, each is counted into the tiles it may cover. After the
    // barrier, not as it is stored: on CPUs an atomic waits for the stores before it.
    barrier(CLK_LOCAL_MEM_FENCE | CLK_GLOBAL_MEM_FENCE);
    const uint count = used - group_first_slot(shot, (int)get_group_id(0));
    if (get_local_id(0) == 0) group_records[get_group_id(0)] = count;
    bin_records(shot, boxes, count, tile_counts, 0);
}
