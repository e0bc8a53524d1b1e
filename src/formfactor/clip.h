// Clipping a convex polygon to a half-space, with a bound on the vertices it returns that holds
// for any input, rounding included.
#pragma once

#include <glm/glm.hpp>

#include "core/error.h"

namespace hemirad::formfactor {

// Lexicographic order of points: a crossing point is computed from the smaller endpoint of its
// edge, so an edge two polygons share is cut at bit-identical points whichever way each walks it.
inline bool lexicographically_less(const glm::dvec3& a, const glm::dvec3& b) {
    if (a.x != b.x) return a.x < b.x;
    if (a.y != b.y) return a.y < b.y;
    return a.z < b.z;
}

// Keeps the part of the polygon in[0, n) where value(v) >= 0 and writes it to out, returning its
// vertex count: at most n + 1, so out needs room for n + 1 vertices. crossing(a, b, fa, fb) is the
// point where the edge from a (value fa) to b (value fb) meets the plane; one of fa, fb is >= 0,
// the other < 0.
//
// Sutherland–Hodgman keeps every vertex at or above the plane and adds a point at every sign
// change along the boundary. A convex polygon changes sign at most twice and so gains at most one
// vertex. Rounding breaks that for a polygon lying almost in the plane: its values are all
// rounding noise and can change sign four or six times, each extra pair adding a vertex (a
// double-sided cylinder under a rotated, scaled node overran a buffer sized for one). So only the
// run of vertices at or above the plane that holds the largest value (the first on ties) is kept,
// with the crossings on the two edges that bound it. With at most two sign changes (every convex
// polygon in exact arithmetic) that is plain Sutherland–Hodgman, vertex for vertex and in the same
// order; with more, the runs left out lie within rounding of the plane. kernels/hemicube.cl
// implements the same rule.
template <class Vertex, class Value, class Crossing>
int clip_convex(const Vertex* in, int n, Value value, Crossing crossing, Vertex* out) {
    constexpr int kMax = 16;  // callers clip triangles and quads through at most 5 planes: n <= 8
    if (n > kMax) throw InternalError("clip_convex: a polygon of more than 16 vertices");
    double f[kMax];
    int top = 0;
    for (int i = 0; i < n; ++i) {
        f[i] = value(in[i]);
        if (f[i] > f[top]) top = i;
    }
    if (n == 0 || !(f[top] >= 0.0)) return 0;
    // The kept run [first, first + length) (indices mod n) around the largest value.
    int first = top, length = 1;
    while (length < n && f[(first + n - 1) % n] >= 0.0) {
        first = (first + n - 1) % n;
        ++length;
    }
    while (length < n && f[(first + length) % n] >= 0.0) ++length;
    const auto kept = [&](int i) { return (i - first + n) % n < length; };

    int m = 0;
    for (int i = 0; i < n; ++i) {
        const int j = (i + 1) % n;
        if (kept(i)) out[m++] = in[i];
        if (kept(i) != kept(j)) out[m++] = crossing(in[i], in[j], f[i], f[j]);  // a true sign change
    }
    return m;
}

// Points, each crossing computed from the lexicographically smaller end of its edge.
template <class Plane>
int clip_convex(const glm::dvec3* in, int n, Plane plane, glm::dvec3* out) {
    const auto crossing = [](const glm::dvec3& a, const glm::dvec3& b, double fa, double fb) {
        const bool a_first = lexicographically_less(a, b);
        const glm::dvec3& p = a_first ? a : b;
        const glm::dvec3& q = a_first ? b : a;
        const double fp = a_first ? fa : fb, fq = a_first ? fb : fa;
        return p + (q - p) * (fp / (fp - fq));
    };
    return clip_convex(in, n, plane, crossing, out);
}

}  // namespace hemirad::formfactor
