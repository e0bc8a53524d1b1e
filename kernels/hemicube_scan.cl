// Stages 2 and 3, scan and scatter (included by hemicube.cl): per-tile list offsets from
// setup's tile counts, then each record's index into the list of every tile it may cover.

// One work-group: exclusive prefix sum of the tile counts, tile by tile and within a tile copy
// by copy, into list offsets (and the scatter cursors, laid out as the counts): a tile's list is
// offsets[tile * COPIES] up to offsets[(tile + 1) * COPIES]. offsets[tiles * COPIES] is the
// total, also in sums[elements + 1], which the host checks against the list capacity. The
// counts are left at zero for the next shot's setup (the host zeroes them only when they are
// new, or after a launch that failed part-way).
__kernel __attribute__((reqd_work_group_size(HEMIRAD_SCAN_WG, 1, 1))) void scan(
    const HrShot first_shot, __global const HrShot* more_shots, __global uint* tile_counts,
    __global uint* offsets, __global uint* cursors, __global long* sums, __global const uint* group_records,
    const int groups) {
    const size_t b = get_global_id(1);
    const HrShot shot_value = batch_shot(first_shot, more_shots, b);
    const HrShot* shot = &shot_value;
    tile_counts += b * counter_stride(shot);
    offsets += b * (counter_stride(shot) + 1);
    cursors += b * counter_stride(shot);
    sums += b * sum_stride(shot);
    __local uint partial[HEMIRAD_SCAN_WG];
    const int lid = (int)get_local_id(0);
    const int tiles = shot->tile_base[HR_FACES];
    const int entries = tiles * HEMIRAD_COUNT_COPIES;
    const int chunk = (entries + HEMIRAD_SCAN_WG - 1) / HEMIRAD_SCAN_WG;
    const int begin = min(lid * chunk, entries), end = min(begin + chunk, entries);
    uint sum = 0;
    for (int t = begin; t < end; ++t) sum += tile_counts[t % HEMIRAD_COUNT_COPIES * tiles + t / HEMIRAD_COUNT_COPIES];
    partial[lid] = sum;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int step = 1; step < HEMIRAD_SCAN_WG; step <<= 1) {  // Hillis-Steele, inclusive
        const uint add = lid >= step ? partial[lid - step] : 0u;
        barrier(CLK_LOCAL_MEM_FENCE);
        partial[lid] += add;
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    uint run = partial[lid] - sum;
    for (int t = begin; t < end; ++t) {
        const int counter = t % HEMIRAD_COUNT_COPIES * tiles + t / HEMIRAD_COUNT_COPIES;
        offsets[t] = run;
        cursors[counter] = run;
        run += tile_counts[counter];
        tile_counts[counter] = 0;  // for the next shot's setup, which counts into it
    }
    if (lid == HEMIRAD_SCAN_WG - 1) {
        offsets[entries] = partial[lid];
        sums[shot->elements + 1] = partial[lid];  // read back with the sums
    }
    // The most records one of the launch's `groups` setup work-groups made, also read back.
    barrier(CLK_LOCAL_MEM_FENCE);
    group_records += b * group_stride(shot);
    uint most = 0;
    for (int g = lid; g < groups; g += HEMIRAD_SCAN_WG) most = max(most, group_records[g]);
    partial[lid] = most;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int step = HEMIRAD_SCAN_WG / 2; step > 0; step >>= 1) {
        if (lid < step) partial[lid] = max(partial[lid], partial[lid + step]);
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) sums[shot->elements + 4] = partial[0];
}

// As setup's counting (the same work-groups, so the same counter copies): the index of each
// record in the list of every tile it may cover. The order within a list varies from run to
// run; the raster's result does not depend on it.
__kernel __attribute__((reqd_work_group_size(HEMIRAD_WG, 1, 1))) void scatter(
    const HrShot first_shot, __global const HrShot* more_shots, __global const HrBox* boxes,
    __global const uint* group_records, __global uint* cursors, __global uint* lists) {
    const size_t b = get_global_id(1);
    const HrShot shot_value = batch_shot(first_shot, more_shots, b);
    const HrShot* shot = &shot_value;
    boxes += b * record_stride(shot);
    group_records += b * group_stride(shot);
    cursors += b * counter_stride(shot);
    lists += b * (size_t)shot->list_capacity;
    bin_records(shot, boxes, group_records[get_group_id(0)], cursors, lists);
}
