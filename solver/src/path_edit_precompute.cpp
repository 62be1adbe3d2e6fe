// Validation, rows and factorization of a path-editing problem (path_edit.h).
#include "path_edit_internal.h"

#include <array>
#include <tuple>

#include "mocapedit/two_threads.h"

namespace mocapedit {
namespace detail {
namespace {

// ---------------------------------------------------------------------------------------
// Validation.

constexpr char kWhere[] = "PathEdit";

inline void CheckIndex(int v, int n, const char* what, Eigen::Index i) {
  if (__builtin_expect(static_cast<unsigned>(v) >= static_cast<unsigned>(n), 0)) {
    std::ostringstream s;
    s << what << " " << i << " refers to vertex " << v << ", outside 0.." << n - 1;
    throw InvalidInput(kWhere, s.str());
  }
}

Eigen::VectorXd Weights(const Eigen::VectorXd& w, Eigen::Index n, const char* what, bool allow_inf) {
  if (w.size() == 0) return Eigen::VectorXd::Ones(n);
  if (w.size() != n)
    throw InvalidInput(kWhere, std::string(what) + " weights: expected " + std::to_string(n) + ", got " +
                             std::to_string(w.size()));
  for (Eigen::Index i = 0; i < n; ++i) {
    const bool ok = w[i] >= 0 && (std::isfinite(w[i]) || (allow_inf && w[i] == kInf));
    if (!ok)
      throw InvalidInput(kWhere, std::string(what) + " " + std::to_string(i) + " has weight " + std::to_string(w[i]) +
                    (allow_inf ? " (expected >= 0, or +inf for hard)" : " (expected a finite value >= 0)"));
  }
  return w;
}

void ChooseMasters(const PathEditProblem& p, PathEditState& d, const std::vector<char>& hard_vertex) {
  const size_t nr = d.rigid.size();
  d.master1.assign(nr, -1);
  d.master2.assign(nr, -1);
  d.degenerate.assign(nr, 0);
  for (size_t r = 0; r < nr; ++r) {
    const auto& vs = d.rigid[r].vertices;
    std::vector<int> hard;
    for (int v : vs)
      if (hard_vertex[v]) hard.push_back(v);
    const bool rotate = d.rigid[r].mode == RigidMode::kRotate;
    if (rotate && hard.size() > 2) {
      std::vector<ConstraintRef> refs{{ConstraintRef::kRigid, static_cast<int>(r)}};
      std::vector<char> in(d.vertices, 0);
      for (int v : vs) in[v] = 1;
      for (Eigen::Index h = 0; h < p.handles.size(); ++h)
        if (in[p.handles[h]] && d.handle_weights[h] == kInf) refs.push_back({ConstraintRef::kHandle, static_cast<int>(h)});
      for (Eigen::Index l = 0; l < p.links.rows(); ++l)
        if ((in[p.links(l, 0)] || in[p.links(l, 1)]) && d.link_weights[l] == kInf)
          refs.push_back({ConstraintRef::kLink, static_cast<int>(l)});
      throw ContradictionError("a rotating rigid range holds hard constraints at " + std::to_string(hard.size()) +
                                   " vertices; it can hold at most two: " + Describe(refs),
                               refs, 0.0);
    }
    // The masters are its hard vertices, else those farthest apart.
    int m1 = -1, m2 = -1;
    if (hard.size() >= 2)
      m1 = hard[0], m2 = hard[1];
    else
      std::tie(m1, m2) = RangeMasters(vs, [&](int v) { return d.z[v]; }, hard.empty() ? -1 : hard[0]);
    d.master1[r] = m1;
    d.master2[r] = m2;
    if (rotate) {
      double extent = 0;
      for (int v : vs) extent = std::max(extent, std::abs(d.z[v] - d.z[m1]));
      const bool too_small = m2 == m1 || std::abs(d.z[m2] - d.z[m1]) <= std::max(p.rigid_min_extent, 1e-9 * d.scale);
      d.degenerate[r] = too_small;
      if (too_small && hard.size() == 2 && std::abs(d.z[hard[0]] - d.z[hard[1]]) > 0) d.degenerate[r] = 0;
    }
  }
}


// Soft handles and links: rows of both steps.
void AddSoftRows(const PathEditProblem& p, const PathEditState& d, Rows& rows) {
  for (Eigen::Index h = 0; h < p.handles.size(); ++h)
    if (d.handle_weights[h] != kInf && d.handle_weights[h] > 0)
      rows.Add({{p.handles[h], 1.0L}}, TargetKind::kHandle, static_cast<int>(h), d.handle_weights[h]);
  for (Eigen::Index l = 0; l < p.links.rows(); ++l)
    if (d.link_weights[l] != kInf && d.link_weights[l] > 0)
      rows.Add({{p.links(l, 0), 1.0L}, {p.links(l, 1), -1.0L}}, TargetKind::kLink, static_cast<int>(l),
               d.link_weights[l]);
}

// The validated inputs and the rest positions as complex numbers.
// tw, ew: the triangles' and edges' weights (all 1 when not given).
void CopyInputs(const PathEditProblem& p, PathEditState& d, Eigen::VectorXd& tw, Eigen::VectorXd& ew) {
  const int n = static_cast<int>(p.rest.rows());
  d.vertices = n;
  d.rest = p.rest;
  Require(p.rest.allFinite(), kWhere, "rest positions must be finite");
  d.z.resize(n);
  d.scale = 1.0;
  for (int v = 0; v < n; ++v) {
    d.z[v] = C(p.rest, v);
    d.scale = std::max({d.scale, std::abs(p.rest(v, 0)), std::abs(p.rest(v, 1))});
  }
  tw = Weights(p.triangle_weights, p.triangles.rows(), "triangle", false);
  ew = Weights(p.edge_weights, p.edges.rows(), "edge", false);
  d.handle_weights = Weights(p.handle_weights, p.handles.size(), "handle", true);
  d.link_weights = Weights(p.link_weights, p.links.rows(), "link", true);
  d.handles = p.handles;
  d.links = p.links;
  d.edges = p.edges;
  for (Eigen::Index t = 0; t < p.triangles.rows(); ++t)
    for (int c = 0; c < 3; ++c) CheckIndex(p.triangles(t, c), n, "triangle", t);
  d.edge_length.resize(static_cast<size_t>(p.edges.rows()));
  for (Eigen::Index e = 0; e < p.edges.rows(); ++e) {
    for (int c = 0; c < 2; ++c) CheckIndex(p.edges(e, c), n, "edge", e);
    d.edge_length[e] = std::sqrt(std::norm(d.z[p.edges(e, 1)] - d.z[p.edges(e, 0)]));
  }
  for (Eigen::Index h = 0; h < p.handles.size(); ++h) CheckIndex(p.handles[h], n, "handle", h);
  for (Eigen::Index l = 0; l < p.links.rows(); ++l) {
    for (int c = 0; c < 2; ++c) CheckIndex(p.links(l, c), n, "link", l);
    if (p.links(l, 0) == p.links(l, 1)) throw InvalidInput(kWhere,
                                                           "link " + std::to_string(l) + " ties a vertex to itself");
  }
  d.rigid_min_extent = p.rigid_min_extent;
  if (p.vertex_times.size() != 0) {
    Require(p.vertex_times.size() == n, kWhere, "vertex times: expected " + std::to_string(n) + ", got " +
                                            std::to_string(p.vertex_times.size()));
    Require(p.vertex_times.allFinite(), kWhere, "vertex times must be finite");
    d.times.assign(p.vertex_times.data(), p.vertex_times.data() + n);
  }
}

// The rigid range of each vertex, and each range's masters.
void SetRigidRanges(const PathEditProblem& p, PathEditState& d) {
  const int n = d.vertices;
  d.rigid = p.rigid;
  d.rigid_of.assign(n, -1);
  for (size_t r = 0; r < d.rigid.size(); ++r) {
    if (d.rigid[r].vertices.empty()) throw InvalidInput(kWhere, "rigid range " + std::to_string(r) + " is empty");
    for (int v : d.rigid[r].vertices) {
      CheckIndex(v, n, "rigid range", static_cast<Eigen::Index>(r));
      if (d.rigid_of[v] >= 0)
        throw InvalidInput(kWhere, "rigid ranges " + std::to_string(d.rigid_of[v]) + " and " + std::to_string(r) +
                           " share vertex " + std::to_string(v));
      d.rigid_of[v] = static_cast<int>(r);
    }
    if (d.rigid[r].mode == RigidMode::kTranslate) d.has_translate = true;
  }
  std::vector<char> hard_vertex(n, 0);
  for (Eigen::Index h = 0; h < p.handles.size(); ++h)
    if (d.handle_weights[h] == kInf) hard_vertex[p.handles[h]] = 1;
  for (Eigen::Index l = 0; l < p.links.rows(); ++l)
    if (d.link_weights[l] == kInf) hard_vertex[p.links(l, 0)] = hard_vertex[p.links(l, 1)] = 1;
  ChooseMasters(p, d, hard_vertex);
  d.boundary_edges.assign(d.rigid.size(), {});
}

// Step 1 rows: triangles, then soft handles and links.
void Step1Rows(const PathEditProblem& p, const Eigen::VectorXd& tw, PathEditState& d) {
  const auto range_of = [&](int v) { return d.rigid_of[v]; };
  d.rows1.Reserve(p.triangles.rows() + p.handles.size() + p.links.rows(),
                  3 * p.triangles.rows() + p.handles.size() + 2 * p.links.rows());
  for (Eigen::Index t = 0; t < p.triangles.rows(); ++t) {
    const int i = p.triangles(t, 0), j = p.triangles(t, 1), k = p.triangles(t, 2);
    const Cplx frame = d.z[k] - d.z[j];
    if (!(std::norm(frame) > 1e-24 * d.scale * d.scale)) {
      std::ostringstream s;
      s << "triangle " << t << ": its frame vertices " << j << " and " << k << " share a rest position";
      throw InvalidInput(kWhere, s.str());
    }
    if (tw[t] == 0 || InOneRange(range_of, {i, j, k})) continue;
    const ShapeTerm<long double> term = MakeShapeTerm(i, j, k, d.zl(i), d.zl(j), d.zl(k));
    if (tw[t] == 1.0)
      d.rows1.AddShape(term, static_cast<int>(t));
    else
      d.rows1.Add(Row(term), TargetKind::kZero, static_cast<int>(t), tw[t]);
  }
  AddSoftRows(p, d, d.rows1);
  d.rows1.Finish();
}

// Step 2 rows: edges, then soft handles and links. Also lists each rigid range's boundary
// edges.
void Step2Rows(const PathEditProblem& p, const Eigen::VectorXd& ew, PathEditState& d) {
  const auto range_of = [&](int v) { return d.rigid_of[v]; };
  d.rows2.Reserve(p.edges.rows() + p.handles.size() + p.links.rows(),
                  2 * p.edges.rows() + p.handles.size() + 2 * p.links.rows());
  for (Eigen::Index e = 0; e < p.edges.rows(); ++e) {
    const int j = p.edges(e, 0), k = p.edges(e, 1);
    const int rj = d.rigid_of[j], rk = d.rigid_of[k];
    if (rj != rk) {
      if (rj >= 0) d.boundary_edges[rj].push_back(static_cast<int>(e));
      if (rk >= 0) d.boundary_edges[rk].push_back(static_cast<int>(e));
    }
    if (ew[e] == 0 || j == k || InOneRange(range_of, {j, k})) continue;
    if (ew[e] == 1.0)
      d.rows2.AddExact({{k, 1.0}, {j, -1.0}}, TargetKind::kEdge, static_cast<int>(e));
    else
      d.rows2.Add(Row(EdgeTerm{j, k}), TargetKind::kEdge, static_cast<int>(e), ew[e]);
  }
  AddSoftRows(p, d, d.rows2);
  d.rows2.Finish();
}

// Step 1's response to each handle position and link offset, one solve each
// (PathEditProblem::precompute_responses).
void PrecomputeResponses(PathEditState& d) {
  const Eigen::Index nh = d.handles.size(), nl = d.links.rows();
  Trajectory2 hp = Trajectory2::Zero(nh, 2), lo = Trajectory2::Zero(nl, 2);
  std::vector<Cplx> x;
  SolveShape(d, hp, lo, 0.0, 0.0, 1.0, false, x, d.response_info);
  d.response_base = x;
  auto response = [&](Trajectory2& values, Eigen::Index k, std::vector<Cplx>& out) {
    values(k, 0) = 1.0;
    StepInfo info;
    SolveShape(d, hp, lo, 0.0, 0.0, 1.0, false, x, info);
    values(k, 0) = 0.0;
    out.resize(x.size());
    for (size_t v = 0; v < x.size(); ++v) out[v] = x[v] - d.response_base[v];
    d.response_info.refinements = std::max(d.response_info.refinements, info.refinements);
  };
  d.handle_response.resize(static_cast<size_t>(nh));
  d.link_response.resize(static_cast<size_t>(nl));
  for (Eigen::Index h = 0; h < nh; ++h) response(hp, h, d.handle_response[static_cast<size_t>(h)]);
  for (Eigen::Index l = 0; l < nl; ++l) response(lo, l, d.link_response[static_cast<size_t>(l)]);
  d.responses = true;
}

// Builds both steps' rows, eliminates and assembles them, and factors them. The two
// steps' systems are independent until solved: a large problem builds them on two
// threads, orders step 1 two ways on two threads, then factors both steps at once (when
// the BLAS may be called from two threads).
void BuildSteps(const PathEditProblem& p, const Eigen::VectorXd& tw, const Eigen::VectorXd& ew, PathEditState& d) {
  auto assemble1 = [&] {
    Step1Rows(p, tw, d);
    BuildElimination(d, true, d.elim1);
    AssembleStep(d.rows1, d.elim1, d.step1);
    FindBetaRows(d.rows1, d.elim1, d.step1);
  };
  auto assemble2 = [&] {
    Step2Rows(p, ew, d);
    BuildElimination(d, false, d.elim2);
    AssembleStep(d.rows2, d.elim2, d.step2);
    FindBetaRows(d.rows2, d.elim2, d.step2);
  };
  const bool large = d.vertices >= kParallelStepsVertices;
  if (large) {
    OnTwoThreads(assemble1, assemble2);
  } else {
    assemble1();
    assemble2();
  }
  // Step 2 in CHOLMOD's AMD order: its edges (no triangles) fill less, and a dissection
  // does not reduce its flops.
  const CandidateOrders orders1 = OrderCandidates(d.step1, d, d.elim1, large);
  auto factor1 = [&] { Factor(d.step1, orders1, p.force_qr); };
  auto factor2 = [&] { Factor(d.step2, CandidateOrders{}, p.force_qr); };
  if (large && Blas().concurrent) {
    OnTwoThreads(factor1, factor2);
  } else {
    factor1();
    factor2();
  }
}

}  // namespace
}  // namespace detail

void AppendChainTerms(const Eigen::Ref<const Trajectory2>& rest, int first, int count, double min_baseline,
                      IndexTriples& triangles, IndexPairs& edges) {
  detail::Require(first >= 0 && count >= 0 && first + count <= rest.rows(), detail::kWhere,
                  "chain vertices outside the rest positions");
  detail::Require(min_baseline >= 0 && std::isfinite(min_baseline), detail::kWhere,
                  "min_baseline must be a finite value >= 0");
  std::vector<std::array<int, 3>> tri;
  tri.reserve(static_cast<size_t>(std::max(count - 2, 0)));
  detail::ChainFrames(rest, first, count, min_baseline,
                      [&](int i, int a, int b) { tri.push_back({first + i, first + a, first + b}); });
  const Eigen::Index t0 = triangles.rows(), e0 = edges.rows();
  triangles.conservativeResize(t0 + static_cast<Eigen::Index>(tri.size()), 3);
  for (size_t k = 0; k < tri.size(); ++k)
    triangles.row(t0 + static_cast<Eigen::Index>(k)) << tri[k][0], tri[k][1], tri[k][2];
  const int ne = std::max(count - 1, 0);
  edges.conservativeResize(e0 + ne, 2);
  detail::ChainEdges(count, [&](int j, int k) { edges.row(e0 + j) << first + j, first + k; });
}

PathEditData::PathEditData() = default;
PathEditData::~PathEditData() = default;
PathEditData::PathEditData(PathEditData&&) noexcept = default;
PathEditData& PathEditData::operator=(PathEditData&&) noexcept = default;

void PathEditPrecompute(const PathEditProblem& p, PathEditData& data) {
  using namespace detail;
  auto d = std::make_unique<PathEditState>();
  Eigen::VectorXd tw, ew;
  CopyInputs(p, *d, tw, ew);
  SetRigidRanges(p, *d);
  BuildSteps(p, tw, ew, *d);
  if (p.precompute_responses) PrecomputeResponses(*d);
  data.handle_count = static_cast<int>(p.handles.size());
  data.link_count = static_cast<int>(p.links.rows());
  data.state = std::move(d);
}

}  // namespace mocapedit
