// PathEditSolve: the rigid shortcut, step 1, the ranges' rotations and step 2 (path_edit.h).
#include "path_edit_internal.h"

namespace mocapedit {
namespace detail {
namespace {

constexpr char kWhere[] = "PathEdit";

// c = sqrt(w) target - G beta, per row, in extended precision. Triangle rows have no
// target; only rows listed in beta_rows read beta.
template <typename Scalar, typename T>
void RowConstants(const Rows& rows, const StepSystem<Scalar>& s, const std::vector<T>& beta,
                  const Eigen::Ref<const Trajectory2>& handle_positions, const Eigen::Ref<const Trajectory2>& link_offsets,
                  const std::vector<Cplx>& edge_targets, std::vector<T>& c) {
  using R = typename T::value_type;
  c.resize(rows.size());
  for (int r = 0; r < rows.size(); ++r) {
    T t;
    switch (rows.target[r]) {
      case TargetKind::kZero: c[r] = T(0); continue;
      case TargetKind::kHandle: t = T(C(handle_positions, rows.target_index[r])); break;
      case TargetKind::kLink: t = T(C(link_offsets, rows.target_index[r])); break;
      case TargetKind::kEdge: t = T(edge_targets[rows.target_index[r]]); break;
    }
    c[r] = rows.sqrt_weight[r] == 1.0L ? t : t * static_cast<R>(rows.sqrt_weight[r]);
  }
  for (int r : s.beta_rows)
    for (int p = rows.ptr[r]; p < rows.ptr[r + 1]; ++p) c[r] -= T(rows.Extended(p)) * beta[rows.vertex[p]];
}

// Positions from unknowns: x_v = sum e u + beta_v (rounded once to double).
template <typename T>
void Expand(const Elimination& e, const CVec& u, const std::vector<T>& beta, std::vector<Cplx>& x) {
  x.resize(e.vertices);
  for (int v = 0; v < e.vertices; ++v) {
    if (e.plain_col[v] >= 0) {
      x[v] = u[e.plain_col[v]];
    } else if (e.e_ptr[v] == e.e_ptr[v + 1]) {
      x[v] = Cplx(beta[v]);
    } else {
      LCplx acc = LCplx(beta[v]);
      for (int q = e.e_ptr[v]; q < e.e_ptr[v + 1]; ++q) acc += e.e_coeff[q] * LCplx(u[e.e_col[q]]);
      x[v] = Cplx(acc);
    }
  }
}

// Starting unknowns: each column's root moved by the similarity z -> a z + b, or taken
// from `from`.
CVec Start(const Elimination& e, const std::vector<Cplx>& z, Cplx a, Cplx b, const std::vector<Cplx>* from) {
  CVec u(e.columns);
  for (int v = 0; v < e.vertices; ++v)
    if (e.root[v] == v && e.col[v] >= 0) u[e.col[v]] = from ? (*from)[v] : a * z[v] + b;
  return u;
}

// One step: constants from the handle positions and offsets, refinement from u, positions.
// Extended precision where the step's conditioning needs it.
template <typename T, typename Scalar, typename TieOffset>
void SolveWith(const PathEditState& d, const Elimination& e, const Rows& rows, const StepSystem<Scalar>& s,
               const Eigen::Ref<const Trajectory2>& handle_positions, const Eigen::Ref<const Trajectory2>& link_offsets,
               TieOffset offset, const std::vector<Cplx>& edge_targets, bool check, double scale, CVec u,
               std::vector<Cplx>& x, StepInfo& info) {
  // Scratch kept per thread: the row constants are all written below, and resizing a
  // vector of extended complex values to the size it had costs nothing.
  thread_local std::vector<T> beta, c;
  ComputeBeta(d, e, handle_positions, offset, beta);
  if (check) CheckConsistency(d, e, handle_positions, offset, beta);
  RowConstants(rows, s, beta, handle_positions, link_offsets, edge_targets, c);
  SolveStep(s, c, scale, u, info);
  Expand(e, u, beta, x);
}

template <typename Scalar, typename TieOffset>
void Solve(const PathEditState& d, const Elimination& e, const Rows& rows, const StepSystem<Scalar>& s,
           const Eigen::Ref<const Trajectory2>& handle_positions, const Eigen::Ref<const Trajectory2>& link_offsets,
           TieOffset offset, const std::vector<Cplx>& edge_targets, bool check, double scale, CVec u,
           std::vector<Cplx>& x, StepInfo& info) {
  if (s.extended || s.use_qr)
    SolveWith<LCplx>(d, e, rows, s, handle_positions, link_offsets, offset, edge_targets, check, scale, u, x, info);
  else
    SolveWith<Cplx>(d, e, rows, s, handle_positions, link_offsets, offset, edge_targets, check, scale, u, x, info);
}

}  // namespace

void SolveShape(const PathEditState& d, const Eigen::Ref<const Trajectory2>& handle_positions,
                const Eigen::Ref<const Trajectory2>& link_offsets, Cplx a, Cplx b, double scale, bool check,
                std::vector<Cplx>& x1, StepInfo& info) {
  auto offset = [&](int t) -> LCplx {
    const Tie& tie = d.elim1.ties[t];
    return tie.kind == TieKind::kLink ? LCplx(C(link_offsets, tie.index)) : tie.rest;
  };
  Solve(d, d.elim1, d.rows1, d.step1, handle_positions, link_offsets, offset, {}, check, scale,
        Start(d.elim1, d.z, a, b, nullptr), x1, info);
}

namespace {

// The best rigid motion (and similarity, to start from) fitting the handles and link
// offsets: z -> rot z + (pbar - rot zbar), z -> sim z + (pbar - sim zbar).
struct HandleFit {
  Cplx zbar = 0, pbar = 0;
  double wsum = 0;
  Cplx rot = 1.0, sim = 1.0;
};

HandleFit FitHandles(const PathEditState& d, const Eigen::Ref<const Trajectory2>& handle_positions,
                     const Eigen::Ref<const Trajectory2>& link_offsets) {
  HandleFit f;
  auto weight = [](double w) { return w == kInf ? 1.0 : std::min(w, 1.0); };
  for (Eigen::Index h = 0; h < d.handles.size(); ++h) {
    const double w = weight(d.handle_weights[h]);
    f.zbar += w * d.z[d.handles[h]];
    f.pbar += w * C(handle_positions, h);
    f.wsum += w;
  }
  if (f.wsum > 0) f.zbar /= f.wsum, f.pbar /= f.wsum;
  Cplx cross = 0;
  double zz = 0;
  for (Eigen::Index h = 0; h < d.handles.size(); ++h) {
    const double w = weight(d.handle_weights[h]);
    const Cplx dz = d.z[d.handles[h]] - f.zbar;
    cross += w * std::conj(dz) * (C(handle_positions, h) - f.pbar);
    zz += w * std::norm(dz);
  }
  for (Eigen::Index l = 0; l < d.links.rows(); ++l) {
    const double w = weight(d.link_weights[l]);
    const Cplx dz = d.z[d.links(l, 0)] - d.z[d.links(l, 1)];
    cross += w * std::conj(dz) * C(link_offsets, l);
    zz += w * std::norm(dz);
  }
  f.rot = std::abs(cross) > 0 ? cross / std::abs(cross) : Cplx(1.0);
  f.sim = zz > 0 && std::abs(cross) > 0 ? cross / zz : Cplx(1.0);
  return f;
}

// Constraints one rigid motion meets are met by exactly that motion: fills the result and
// returns true when they are.
bool RigidShortcut(const PathEditState& d, const Eigen::Ref<const Trajectory2>& handle_positions,
                   const Eigen::Ref<const Trajectory2>& link_offsets, const HandleFit& f, double scale,
                   PathEditResult& result) {
  if (!(f.wsum > 0)) return false;
  const Cplx rot = f.rot, shift = f.pbar - rot * f.zbar;
  const double tol = kRigidTolerance * scale;
  bool rigid = !(d.has_translate && rot != Cplx(1.0));
  for (Eigen::Index h = 0; rigid && h < d.handles.size(); ++h)
    if (d.handle_weights[h] > 0) rigid = std::abs(rot * d.z[d.handles[h]] + shift - C(handle_positions, h)) <= tol;
  for (Eigen::Index l = 0; rigid && l < d.links.rows(); ++l)
    if (d.link_weights[l] > 0)
      rigid = std::abs(rot * (d.z[d.links(l, 0)] - d.z[d.links(l, 1)]) - C(link_offsets, l)) <= tol;
  if (!rigid) return false;
  const int n = d.vertices;
  result.positions.resize(n, 2);
  for (int v = 0; v < n; ++v) {
    const Cplx x = rot * d.z[v] + shift;
    result.positions.row(v) << x.real(), x.imag();
  }
  result.shape = result.positions;
  result.rigid_motion = true;
  result.rigid_angle = std::arg(rot);
  for (size_t r = 0; r < d.rigid.size(); ++r)
    result.rigid_angles[r] = d.rigid[r].mode == RigidMode::kRotate ? result.rigid_angle : 0.0;
  result.step1 = result.step2 = StepInfo{"rigid", 0, 0, 0};
  return true;
}

// Step 1 from the precomputed responses: x1 = base + sum of each response times its handle
// position or link offset, in one pass (after checking the hard constraints agree).
void ShapeFromResponses(const PathEditState& d, const Eigen::Ref<const Trajectory2>& handle_positions,
                        const Eigen::Ref<const Trajectory2>& link_offsets, std::vector<Cplx>& x1, StepInfo& info) {
  if (!d.elim1.extra_ties.empty() || !d.elim1.extra_handles.empty()) {
    std::vector<LCplx> beta;
    auto offset = [&](int t) -> LCplx {
      const Tie& tie = d.elim1.ties[t];
      return tie.kind == TieKind::kLink ? LCplx(C(link_offsets, tie.index)) : tie.rest;
    };
    ComputeBeta(d, d.elim1, handle_positions, offset, beta);
    CheckConsistency(d, d.elim1, handle_positions, offset, beta);
  }
  std::vector<const Cplx*> resp;
  std::vector<Cplx> value;
  for (Eigen::Index h = 0; h < d.handles.size(); ++h)
    if (C(handle_positions, h) != Cplx(0.0)) resp.push_back(d.handle_response[h].data()), value.push_back(C(handle_positions, h));
  for (Eigen::Index l = 0; l < d.links.rows(); ++l)
    if (C(link_offsets, l) != Cplx(0.0)) resp.push_back(d.link_response[l].data()), value.push_back(C(link_offsets, l));
  const int n = d.vertices;
  x1.resize(n);
  const size_t m = resp.size();
  for (int i = 0; i < n; ++i) {
    Cplx acc = d.response_base[i];
    for (size_t k = 0; k < m; ++k) acc += resp[k][i] * value[k];
    x1[i] = acc;
  }
  info = d.response_info;
  info.solver += " (precomputed responses)";
}

// Rotation of each rotating range: its step-1 similarity, or (when it is too small to
// carry one) the step-1 turn of the edges entering and leaving it. 1 for other ranges.
void RangeRotations(const PathEditState& d, const std::vector<Cplx>& x1, std::vector<LCplx>& range_rot,
                    Eigen::VectorXd& angles) {
  const int nr = static_cast<int>(d.rigid.size());
  range_rot.assign(nr, 1.0L);
  for (int r = 0; r < nr; ++r) {
    if (d.rigid[r].mode != RigidMode::kRotate) continue;
    LCplx q = 0;
    if (!d.degenerate[r]) {
      q = (LCplx(x1[d.master2[r]]) - LCplx(x1[d.master1[r]])) / (d.zl(d.master2[r]) - d.zl(d.master1[r]));
    } else {
      for (int e : d.boundary_edges[r]) {
        const int j = d.edges(e, 0), k = d.edges(e, 1);
        q += BoundaryTurn(LCplx(x1[k]) - LCplx(x1[j]), d.zl(k) - d.zl(j));
      }
    }
    range_rot[r] = RangeTurn(q);
    angles[r] = std::atan2(static_cast<double>(range_rot[r].imag()), static_cast<double>(range_rot[r].real()));
  }
}

// Step 2: each edge keeps its rest length along its step-1 direction.
void SolveScale(const PathEditState& d, const Eigen::Ref<const Trajectory2>& handle_positions,
                const Eigen::Ref<const Trajectory2>& link_offsets, const std::vector<Cplx>& x1,
                const std::vector<LCplx>& range_rot, double scale, std::vector<Cplx>& x2, StepInfo& info) {
  std::vector<Cplx> edge_targets(d.edges.rows());
  for (Eigen::Index e = 0; e < d.edges.rows(); ++e) {
    const int j = d.edges(e, 0), k = d.edges(e, 1);
    edge_targets[e] = EdgeTarget(x1[k] - x1[j], d.edge_length[e], d.z[k] - d.z[j]);
  }
  auto offset2 = [&](int t) -> LCplx {
    const Tie& tie = d.elim2.ties[t];
    switch (tie.kind) {
      case TieKind::kLink: return LCplx(C(link_offsets, tie.index));
      case TieKind::kRest: return tie.rest;
      case TieKind::kRotated: return range_rot[tie.index] * tie.rest;
    }
    return tie.rest;
  };
  Solve(d, d.elim2, d.rows2, d.step2, handle_positions, link_offsets, offset2, edge_targets, true, scale,
        Start(d.elim2, d.z, 1.0, 0.0, &x1), x2, info);
}

}  // namespace
}  // namespace detail

void PathEditSolve(const PathEditData& data, const Eigen::Ref<const Trajectory2>& handle_positions,
                   const Eigen::Ref<const Trajectory2>& link_offsets, PathEditResult& result) {
  using namespace detail;
  Require(data.state != nullptr, kWhere, "the data was not precomputed");
  const PathEditState& d = *data.state;
  const int n = d.vertices;
  if (handle_positions.rows() != d.handles.size())
    throw InvalidInput(kWhere, "expected " + std::to_string(d.handles.size()) + " handle positions, got " +
                                   std::to_string(handle_positions.rows()));
  if (link_offsets.rows() != d.links.rows())
    throw InvalidInput(kWhere, "expected " + std::to_string(d.links.rows()) + " link offsets, got " +
                                   std::to_string(link_offsets.rows()));
  Require(handle_positions.allFinite() && link_offsets.allFinite(), kWhere,
          "handle positions and link offsets must be finite");
  result.rigid_angles = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(d.rigid.size()));
  result.rigid_motion = false;
  result.rigid_angle = 0;
  double scale = d.scale;
  for (Eigen::Index h = 0; h < handle_positions.rows(); ++h)
    scale = std::max({scale, std::abs(handle_positions(h, 0)), std::abs(handle_positions(h, 1))});

  const HandleFit fit = FitHandles(d, handle_positions, link_offsets);
  if (RigidShortcut(d, handle_positions, link_offsets, fit, scale, result)) return;
  std::vector<Cplx> x1;
  if (d.responses) {
    ShapeFromResponses(d, handle_positions, link_offsets, x1, result.step1);
  } else {
    const Cplx sim_shift = fit.wsum > 0 ? fit.pbar - fit.sim * fit.zbar : Cplx(0.0);
    SolveShape(d, handle_positions, link_offsets, fit.sim, sim_shift, scale, true, x1, result.step1);
  }
  std::vector<LCplx> range_rot;
  RangeRotations(d, x1, range_rot, result.rigid_angles);
  std::vector<Cplx> x2;
  SolveScale(d, handle_positions, link_offsets, x1, range_rot, scale, x2, result.step2);

  // std::complex<double> is two doubles, real first: the same layout as a row of Trajectory2.
  using Rows2 = Eigen::Map<const Trajectory2>;
  result.positions = Rows2(reinterpret_cast<const double*>(x2.data()), n, 2);
  result.shape = Rows2(reinterpret_cast<const double*>(x1.data()), n, 2);
}

std::pair<double, double> PathEditConditionEstimate(const PathEditData& data) {
  detail::Require(data.state != nullptr, "PathEdit", "the data was not precomputed");
  return {data.state->step1.condition, data.state->step2.condition};
}

}  // namespace mocapedit
