// Culling for lanes setup (HEMIRAD_SETUP_LANES): a lane group's bounding sphere against the
// shooter's base plane (HEMIRAD_CULL), and occlusion culling against the occluder pass's depth
// blocks, per lane group in setup (group_hidden) and per cluster (the cull_clusters kernel,
// between the occluder pass and the final pass). Included by hemicube_setup.cl, after
// hemicube_setup_lanes.cl (its lane types); empty without HEMIRAD_SETUP_LANES.

#if HEMIRAD_SETUP_LANES
// Whether a group's bounding sphere lies wholly behind the base plane, below -eps: then every
// vertex of every element is below the plane, where setup_element would drop it too (it keeps
// an element with a vertex above +eps; the margin of 2 eps dwarfs this test's rounding).
bool group_behind(const HrShot* shot, __global const HrElementLanes* group) {
    const Vec d = vec(group->bound[0] - shot->origin[0], group->bound[1] - shot->origin[1],
                      group->bound[2] - shot->origin[2]);
    return dot3(d, vec(shot->w[0], shot->w[1], shot->w[2])) + group->bound[3] < -shot->eps;
}

// Occlusion culling (setup's `occluded`): whether every cell any element of a lane group could
// cover holds something nearer already, so that setup may drop the group without changing one
// cell. block_depth[b] is the least 1/depth over depth block b's cells in the occluder pass (0
// where a cell was empty); the final raster only adds records, so a cell's winner is at least that
// near. A group is hidden when, on every face its bounding sphere reaches, an upper bound of the
// 1/depth its records could hold at any cell is below block_depth on every block the sphere's
// projection (widened as below) touches. The bound must hold for the values setup and the raster
// compute, not only for the geometry:
// - a cell centre inside a record lies within 2^-17 sqrt2 cells of the element's true projection
//   (its vertices are snapped to 2^-16 cells), where the plane's 1/depth is at most 1/(z - r)
//   (z the sphere centre's depth on the face); beyond it, the plane rises at most 1/c per unit of
//   face coordinate (c the plane's distance from the shooter, the normal a unit vector), so the
//   bound adds delta/c with delta that distance in face units;
// - setup computes c from rounded vertices (any of the element's, or a clipped one): absolute error
//   ~1e-15 |v - origin|, bounded here by 1e-12 times `extent`, which bounds |v - origin| for every
//   point of the bounding sphere (the plane's 1/depth scales by c/c_computed), with c_eff the
//   smallest c less that and a group with c_eff <= 0 never hidden (a plane through the shooter);
// - the rest is rounding of order 1e-15 relative, covered by the factor 1 + 1e-9, and a sphere
//   within 1e-4 of its size from a face's eye plane is never hidden on it, unless it lies wholly
//   outside the face's frustum (beyond a side plane by more than rounding: setup clips to the
//   frustum, and a cell centre lies half a cell inside it), where it covers nothing on the face.
// Triangles repeat their last vertex, so vertex 0 and the normal of live lanes suffice for c.
// The least distance |n . (v - origin)| of a lane group's live elements' planes from the shooter,
// as computed (INFINITY when no lane is live).
double group_plane_distance(const HrShot* shot, __global const HrElementLanes* group) {
    const llong live = convert_long8(vload8(0, group->n)) > 0;
    const ldouble c = fabs(vload8(0, group->normal) * (vload8(0, group->v) - shot->origin[0]) +
                           vload8(1, group->normal) * (vload8(1, group->v) - shot->origin[1]) +
                           vload8(2, group->normal) * (vload8(2, group->v) - shot->origin[2]));
    const ldouble c_live = select((ldouble)(INFINITY), c, live);
    const double4 c_half = fmin(c_live.lo, c_live.hi);
    return fmin(fmin(c_half.x, c_half.y), fmin(c_half.z, c_half.w));
}

// Whether every element inside the sphere bound = {x, y, z, radius} (world), whose planes lie at
// least c_raw from the shooter as group_plane_distance computes it, is hidden (see above).
bool sphere_hidden(const HrShot* shot, const double* bound, double c_raw, __global const double* block_depth) {
    const Vec centre = to_local(shot, vec(bound[0], bound[1], bound[2]));
    const double r = bound[3];
    const double size = fabs(centre.x) + fabs(centre.y) + fabs(centre.z) + r;
    const double extent = size + r;  // >= the 1-norm of any point of the sphere less the origin
    const double c_min = c_raw - 1e-12 * extent;
    if (!(c_min > 0.0) || c_min == INFINITY) return false;

    const int n = shot->n;
    const double per_unit = 0.5 * n;
    const double delta = 0x1p-17 * 1.4142135623730951 * 1.01 / per_unit;  // face units
    const double slack = delta / c_min;
    const double scale = 1.0 + 1e-9 + 4e-12 * extent / c_min;
    for (int face = 0; face < HR_FACES; ++face) {
        const Vec f = to_face(face, centre);
        if (f.z + r <= 0.0) continue;                   // wholly behind this face's eye plane: not on it
        // Wholly beyond one of the face's side planes (|x| = z, |y| = z; a side face's bottom is
        // the base plane, y = 0): its elements, clipped to the frustum, cover none of its cells.
        const double beyond = 1.4142135623730951 * r * (1.0 + 1e-9) + 1e-9 * size;
        if (f.x - f.z > beyond || -f.x - f.z > beyond || f.y - f.z > beyond ||
            (face == 0 ? -f.y - f.z > beyond : -f.y > r * (1.0 + 1e-9) + 1e-9 * size))
            continue;
        if (f.z - r <= 1e-4 * size) return false;       // (near) the eye plane: no bound
        const double near_depth = f.z - r, far_depth = f.z + r;
        const double s_lo = fmin((f.x - r) / near_depth, (f.x - r) / far_depth) - delta;
        const double s_hi = fmax((f.x + r) / near_depth, (f.x + r) / far_depth) + delta;
        const double t_lo = fmin((f.y - r) / near_depth, (f.y - r) / far_depth) - delta;
        const double t_hi = fmax((f.y + r) / near_depth, (f.y + r) / far_depth) + delta;
        const double t0 = face == 0 ? 1.0 : 0.0;
        // Cells whose centre (i + 1/2) may lie in the box, clamped to the face; none: not on it.
        const double x_lo = (s_lo + 1.0) * per_unit - 0.5, x_hi = (s_hi + 1.0) * per_unit - 0.5;
        const double y_lo = (t_lo + t0) * per_unit - 0.5, y_hi = (t_hi + t0) * per_unit - 0.5;
        const int rows = face_rows(face, n);
        if (x_hi < -1.0 || y_hi < -1.0 || x_lo > n || y_lo > rows) continue;
        const int i0 = max(0, (int)floor(x_lo)), i1 = min(n - 1, (int)ceil(x_hi));
        const int j0 = max(0, (int)floor(y_lo)), j1 = min(rows - 1, (int)ceil(y_hi));
        if (i0 > i1 || j0 > j1) continue;
        const double bound = (1.0 / near_depth + slack) * scale;
        __global const double* depth = block_depth + depth_block_base(face, n);
        for (int by = j0 / DEPTH_BLOCK; by <= j1 / DEPTH_BLOCK; ++by)
            for (int bx = i0 / DEPTH_BLOCK; bx <= i1 / DEPTH_BLOCK; ++bx)
                if (!(bound < depth[by * depth_blocks_x(n) + bx])) return false;
    }
    return true;
}

bool group_hidden(const HrShot* shot, __global const HrElementLanes* group, __global const double* block_depth) {
    const double bound[4] = {group->bound[0], group->bound[1], group->bound[2], group->bound[3]};
    return sphere_hidden(shot, bound, group_plane_distance(shot, group), block_depth);
}

// Occlusion culling of whole clusters, between the occluder pass and the final pass: a work-item
// per entry of a shot's row of clusters (clusters, row_length entries a shot), testing the
// cluster's bounding sphere with the least plane distance of its live groups (the bound of
// group_hidden, which holds for any sphere that holds the elements). hidden[entry] is the number
// of the cluster's live lane groups (not wholly behind the base plane) where the occluder pass's
// depths hide it, else 0 (and 0 for an entry that is no cluster to set up: -1, or an occluder,
// -2 - c). The host then launches setup on the clusters not hidden alone: a hidden cluster costs
// no work-group, clear or read.
__kernel void cull_clusters(const HrShot first_shot, __global const HrShot* more_shots,
                            __global const HrElementLanes* element_lanes, __global const int* clusters,
                            const int row_length, __global const double* block_depth,
                            __global const double* cluster_bounds, __global int* hidden) {
    const size_t b = get_global_id(1);
    const int g = (int)get_global_id(0);
    if (g >= row_length) return;
    const HrShot shot_value = batch_shot(first_shot, more_shots, b);
    const HrShot* shot = &shot_value;
    const int cluster = clusters[b * row_length + g];
    int live = 0;
    if (cluster >= 0) {
        double c = INFINITY;
        for (int l = 0; l < HEMIRAD_WG; ++l) {
            const int p = cluster * HEMIRAD_WG + l;
            if (p * HR_SETUP_LANES >= shot->elements) break;
#if HEMIRAD_CULL
            if (group_behind(shot, element_lanes + p)) continue;
#endif
            ++live;
            c = fmin(c, group_plane_distance(shot, element_lanes + p));
        }
        const double bound[4] = {cluster_bounds[4 * cluster], cluster_bounds[4 * cluster + 1],
                                 cluster_bounds[4 * cluster + 2], cluster_bounds[4 * cluster + 3]};
        if (!sphere_hidden(shot, bound, c, block_depth + b * depth_stride(shot->n))) live = 0;
    }
    hidden[b * row_length + g] = live;
}
#endif
