// One step's solve by refinement (path_edit_internal.h).
#include "path_edit_internal.h"

namespace mocapedit::detail {
namespace {

// Scratch vectors of one solve.
struct Work {
  std::vector<Cplx> rr;  // row residuals
};

// The correction for the residual of u: QR of the rectangular system, or the factored
// normal equations. Row residuals are accumulated in extended precision when T is, unless
// `coarse` (a first pass from a start far from the solution, whose correction only needs
// to be accurate to about cond * eps, as any pass's is).
template <typename Scalar, typename T>
void Correction(const StepSystem<Scalar>& s, const std::vector<T>& c, const CVec& u, Work& w,
                bool qr, bool coarse, CVec& delta) {
  w.rr.resize(s.rows);
  if (std::is_same<T, Cplx>::value || coarse) {  // double residuals are enough
    for (int r = 0; r < s.rows; ++r) {
      Cplx acc = Cplx(c[r]);
      for (int p = s.a_ptr[r]; p < s.a_ptr[r + 1]; ++p) acc -= s.a_val[p] * u[s.a_col[p]];
      w.rr[r] = acc;
    }
  } else for (int r = 0; r < s.rows; ++r) {
    long double re = c[r].real(), im = c[r].imag();
    for (int p = s.a_ptr[r]; p < s.a_ptr[r + 1]; ++p) {
      const LCplx a = LCplx(s.a_val[p]) + LCplx(s.a_low[p]);
      const long double ur = u[s.a_col[p]].real(), ui = u[s.a_col[p]].imag();
      re -= a.real() * ur - a.imag() * ui;
      im -= a.real() * ui + a.imag() * ur;
    }
    w.rr[r] = Cplx(static_cast<double>(re), static_cast<double>(im));
  }
  delta.resize(s.cols);
  if constexpr (std::is_same<Scalar, double>::value) {
    if (qr) {
      Eigen::MatrixX2d b(s.rows, 2);
      for (int r = 0; r < s.rows; ++r) b.row(r) << w.rr[r].real(), w.rr[r].imag();
      const auto& qr = s.QR();
      BlasLock lock;
      const Eigen::MatrixX2d x = qr.solve(b);
      for (int j = 0; j < s.cols; ++j) delta[j] = Cplx(x(j, 0), x(j, 1));
      return;
    }
    // A real system acts on x and y alike: solve both as interleaved right-hand sides.
    delta.setZero();
    double* g = reinterpret_cast<double*>(delta.data());
    for (int r = 0; r < s.rows; ++r)
      for (int p = s.a_ptr[r]; p < s.a_ptr[r + 1]; ++p) {
        const double a = s.a_val[p] + s.a_low[p];
        g[2 * s.a_col[p]] += a * w.rr[r].real();
        g[2 * s.a_col[p] + 1] += a * w.rr[r].imag();
      }
    s.SolveInterleaved(g, 2);
  } else {
    if (qr) {
      Eigen::Map<const CVec> b(w.rr.data(), s.rows);
      const auto& qr = s.QR();
      BlasLock lock;
      delta = qr.solve(CVec(b));
      return;
    }
    delta.setZero();
    for (int r = 0; r < s.rows; ++r)
      for (int p = s.a_ptr[r]; p < s.a_ptr[r + 1]; ++p)
        delta[s.a_col[p]] += std::conj(s.a_val[p] + s.a_low[p]) * w.rr[r];
    s.SolveInterleaved(delta.data(), 1);
  }
}

// Solves min |A u - c| from the start u by refinement: each pass removes all but about
// cond * eps of the error (QR: about cond(A) * eps). Returns false when it does not converge.
template <typename Scalar, typename T>
bool Refine(const StepSystem<Scalar>& s, const std::vector<T>& c, double scale, CVec& u, StepInfo& info,
            bool qr) {
  Work w;
  CVec delta;
  const double rate = qr ? std::sqrt(std::max(s.condition, 1.0)) * kEps : s.condition * kEps;
  const double tol = kRefineTolerance * scale;
  double previous = kInf;
  info.refinements = 0;
  for (int it = 0; it < kMaxRefinements; ++it) {
    // Extended residuals: the first pass in double precision, the others extended (and
    // at least one of them).
    const bool coarse = std::is_same<T, LCplx>::value && it == 0;
    Correction(s, c, u, w, qr, coarse, delta);
    u += delta;
    const double size = delta.size() ? std::sqrt(delta.cwiseAbs2().maxCoeff()) : 0.0;
    info.refinements = it + 1;
    info.correction = size;
    if (!std::isfinite(size)) return false;
    // The error left is about rate * size: stop when that is below the tolerance.
    if (!coarse && (10 * rate * size <= tol || size <= tol)) return true;
    if (it >= 1 && size > 0.5 * previous) return size <= 1e-9 * scale;  // stagnation
    previous = size;
  }
  return false;
}

}  // namespace

// Refinement of the normal equations, or of QR when the step uses QR or when the first
// does not converge.
template <typename Scalar, typename T>
void SolveStep(const StepSystem<Scalar>& s, const std::vector<T>& c, double scale, CVec& u, StepInfo& info) {
  info.solver = s.solver;
  info.unknowns = s.cols;
  info.refinements = 0;
  info.correction = 0;
  if (s.cols == 0) return;
  if (s.use_qr) {
    if (!Refine(s, c, scale, u, info, true)) info.solver += " (refinement did not converge)";
    return;
  }
  const CVec start = u;
  if (!Refine(s, c, scale, u, info, false)) {
    u = start;
    info.solver = "SPQR (ill-conditioned)";
    if (!Refine(s, c, scale, u, info, true)) info.solver += " (refinement did not converge)";
  }
}

template void SolveStep(const StepSystem<Cplx>&, const std::vector<Cplx>&, double, CVec&, StepInfo&);
template void SolveStep(const StepSystem<Cplx>&, const std::vector<LCplx>&, double, CVec&, StepInfo&);
template void SolveStep(const StepSystem<double>&, const std::vector<Cplx>&, double, CVec&, StepInfo&);
template void SolveStep(const StepSystem<double>&, const std::vector<LCplx>&, double, CVec&, StepInfo&);

}  // namespace mocapedit::detail
