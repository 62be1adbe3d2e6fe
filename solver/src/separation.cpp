// The separation solve (separation.h): rows gathered by agent, each agent's block of the
// Schur complement, the row forces, and both steps' positions.
#include "separation_internal.h"

#include <cstdint>
#include <cstring>
#include <atomic>

namespace mocapedit {
namespace detail {
namespace {

constexpr char kWhere[] = "SeparationSolve";


// Lists of (index, coefficient) pairs, one list per local row, stored one after another
// (a few allocations per agent rather than one per row).
struct RowLists {
  using Item = std::pair<int, Complex>;
  struct Span {
    const Item *first, *last;
    const Item* begin() const { return first; }
    const Item* end() const { return last; }
  };
  std::vector<int> start{0};  // #rows+1 offsets into items
  std::vector<Item> items;

  size_t rows() const { return start.size() - 1; }
  Span row(size_t k) const { return {items.data() + start[k], items.data() + start[k + 1]}; }
  void Clear() {
    start.assign(1, 0);
    items.clear();
  }
  void CloseRow() { start.push_back(static_cast<int>(items.size())); }
  bool SameRow(size_t k, const RowLists& other, size_t l) const {
    return start[k + 1] - start[k] == other.start[l + 1] - other.start[l] &&
           std::equal(items.begin() + start[k], items.begin() + start[k + 1], other.items.begin() + other.start[l]);
  }
  // A hash of row k's items (equal rows hash alike).
  uint64_t Hash(size_t k) const {
    uint64_t h = 1469598103934665603ull;
    auto mix = [&](uint64_t v) { h = (h ^ v) * 1099511628211ull; };
    for (const auto& [i, c] : row(k)) {
      uint64_t re, im;
      const double parts[2] = {c.real(), c.imag()};
      std::memcpy(&re, &parts[0], sizeof re);
      std::memcpy(&im, &parts[1], sizeof im);
      mix(static_cast<uint64_t>(i));
      mix(re);
      mix(im);
    }
    return h;
  }
  bool operator==(const RowLists& other) const { return start == other.start && items == other.items; }
};

// Entries of an agent's K^-1 between some of its unknowns, grown as rows touch new ones.
template <typename Scalar>
struct InverseBlock {
  using Matrix = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
  std::vector<int> unknowns;      // cached unknowns, in the order of `lower`
  std::vector<int> slot;          // per unknown of the step: index into `unknowns`, -1 if absent
  // K^-1 restricted to `unknowns`, its lower triangle row after row (row p, entries 0 .. p,
  // from p (p + 1) / 2 on); K being Hermitian, the upper one is its conjugate. New unknowns
  // append rows, and half the entries of a square are kept (gigabytes for a crowd of 10,000).
  std::vector<Scalar> lower;
  size_t room = 0;                // rows `lower` has room for

  // The last solve's rows of the agent (their terms), and their G and Schur block.
  RowLists terms, g;
  Eigen::MatrixXd s;
  int64_t columns = 0;  // back-substitutions done so far

  static Scalar Conj(const Scalar& v) {
    if constexpr (std::is_same_v<Scalar, double>) return v;
    else return std::conj(v);
  }

  Scalar At(int i, int j) const {
    const size_t a = static_cast<size_t>(slot[static_cast<size_t>(i)]), b = static_cast<size_t>(slot[static_cast<size_t>(j)]);
    return a >= b ? lower[a * (a + 1) / 2 + b] : Conj(lower[b * (b + 1) / 2 + a]);
  }

  // Makes sure the entries between `needed` unknowns are cached. Returns false when the
  // entries cached before were dropped (and those needed worked out again).
  template <typename Solver>
  bool Ensure(const Solver& solver, int n, const std::vector<int>& needed) {
    bool kept = true;
    if (static_cast<int>(slot.size()) != n) {
      kept = false;
      slot.assign(static_cast<size_t>(n), -1);
      unknowns.clear();
      lower = {};
      room = 0;
    }
    std::vector<int> missing;
    for (int j : needed)
      if (slot[static_cast<size_t>(j)] < 0) missing.push_back(j);
    // Forget unknowns no row needs any more once they outnumber the needed ones.
    if (static_cast<int>(unknowns.size()) + static_cast<int>(missing.size()) > 2 * static_cast<int>(needed.size()) + 32) {
      for (int j : unknowns) slot[static_cast<size_t>(j)] = -1;
      unknowns.clear();
      // (the storage stays for the entries worked out again)
      missing = needed;
      kept = false;
    }
    if (missing.empty()) return kept;
    int lowest = n;  // of the unknowns cached already
    for (int j : unknowns) lowest = std::min(lowest, j);
    const Matrix x = solver.InverseColumns(missing, lowest);
    columns += static_cast<int64_t>(missing.size());
    const Eigen::Index old = static_cast<Eigen::Index>(unknowns.size());
    const Eigen::Index total = old + static_cast<Eigen::Index>(missing.size());
    if (static_cast<size_t>(total) > room) {
      // Half as many rows again (no more than the step's unknowns): doubling made blocks
      // four times the entries they held.
      room = std::max(static_cast<size_t>(total), std::min(static_cast<size_t>(n), room + room / 2));
      lower.reserve(room * (room + 1) / 2);
    }
    lower.resize(static_cast<size_t>(total) * static_cast<size_t>(total + 1) / 2);
    for (int j : missing) {
      slot[static_cast<size_t>(j)] = static_cast<int>(unknowns.size());
      unknowns.push_back(j);
    }
    // Row p = old + c of new column c, entries i <= p: K^-1(unknowns[p], unknowns[i]), the
    // conjugate of column c's entry i. Below min(j, lowest) column c was left undone: its
    // entry i is then column i's entry j, conjugated (i is new there, the cached unknowns
    // lying at or above lowest).
    for (Eigen::Index c = 0; c < static_cast<Eigen::Index>(missing.size()); ++c) {
      const int j = missing[static_cast<size_t>(c)];
      const size_t p = static_cast<size_t>(old + c);
      Scalar* row = lower.data() + p * (p + 1) / 2;
      for (size_t i = 0; i <= p; ++i) {
        const int at = unknowns[i];
        row[i] = at >= std::min(j, lowest) ? Conj(x(at, c)) : x(j, slot[static_cast<size_t>(at)] - old);
      }
    }
    return kept;
  }
};

// The rows that touch one agent, and that agent's block of the Schur complement.
struct AgentRows {
  std::vector<int> rows;       // global rows, ascending
  RowLists terms;              // per local row: (local vertex, weight * direction)
  // The step's block, held by the agent's SeparationCache entry for the step:
  const Eigen::MatrixXd* s = nullptr;  // local rows by local rows: Re(g^H K^-1 g)
  const RowLists* g = nullptr;         // per local row: (unknown, coefficient)
  std::vector<double> base;    // per local row: its value without rows
  Eigen::VectorXcd y0;         // the step's unknowns without rows
};

// Fills the agent's Schur block for one step in `cache`: S = Re(G^H K^-1 G). A row's value
// is Re(sum conj(c) z) = Re(g^H y) + constant with g_j = c conj(a_j), so S only needs the
// entries of K^-1 between the unknowns the rows touch; those are kept in `cache` and
// only new unknowns cost a back-substitution. G and S depend on the rows' terms alone (not on
// y0 nor on the map's constants, so step 2's can be formed before step 1 is solved): when
// the agent's rows are those of the last solve (as re-sent rows whose linearisation did
// not change are), they stay in `cache` as they are.
template <typename Solver, typename MapFn, typename Scalar>
void AgentMatrix(const Solver& solver, int n, MapFn map, const RowLists& terms, InverseBlock<Scalar>* cache) {
  const int r = static_cast<int>(terms.rows());
  if (static_cast<int>(cache->slot.size()) == n && cache->terms == terms) return;
  RowLists g;
  g.items.reserve(terms.items.size() * 2);
  std::vector<int> needed;
  std::vector<RowLists::Item> col;
  for (int k = 0; k < r; ++k) {
    auto add = [&](int j, Complex v) {
      for (auto& e : col)
        if (e.first == j) {
          e.second += v;
          return;
        }
      col.emplace_back(j, v);
    };
    col.clear();
    for (const auto& [i, c] : terms.row(static_cast<size_t>(k))) {
      const Map m = map(i);
      add(m.j0, c * std::conj(m.a0));
      if (m.j1 >= 0) add(m.j1, c * std::conj(m.a1));
    }
    g.items.insert(g.items.end(), col.begin(), col.end());
    g.CloseRow();
    for (const auto& e : col) needed.push_back(e.first);
  }
  std::sort(needed.begin(), needed.end());
  needed.erase(std::unique(needed.begin(), needed.end()), needed.end());
  const bool kept = cache->Ensure(solver, n, needed);
  // Rows sent again unchanged keep their entries of the last solve's block, as long as
  // the cached entries of K^-1 they came from were kept (the same values either way).
  std::vector<int> old(static_cast<size_t>(r), -1);
  if (kept && cache->s.rows() == static_cast<Eigen::Index>(cache->terms.rows())) {
    std::vector<std::pair<uint64_t, int>> known(cache->terms.rows());
    for (size_t l = 0; l < known.size(); ++l) known[l] = {cache->terms.Hash(l), static_cast<int>(l)};
    std::sort(known.begin(), known.end());
    for (int k = 0; k < r; ++k) {
      const uint64_t h = terms.Hash(static_cast<size_t>(k));
      for (auto it = std::lower_bound(known.begin(), known.end(), std::make_pair(h, -1));
           it != known.end() && it->first == h; ++it)
        if (terms.SameRow(static_cast<size_t>(k), cache->terms, static_cast<size_t>(it->second))) {
          old[static_cast<size_t>(k)] = it->second;
          break;
        }
    }
  }
  // The upper triangle column by column (both blocks are column-major: the entries taken over
  // from the last solve's block are read down its columns), then the lower one by symmetry.
  Eigen::MatrixXd s(r, r);
  for (int l = 0; l < r; ++l) {
    const int ol = old[static_cast<size_t>(l)];
    for (int k = 0; k <= l; ++k) {
      const int ok = old[static_cast<size_t>(k)];
      if (ok >= 0 && ol >= 0) {
        s(k, l) = cache->s(ok, ol);
        continue;
      }
      if constexpr (std::is_same_v<Scalar, double>) {
        // A real K^-1: the real part of conj(gi) gj K^-1(i, j) is Re(conj(gi) gj) K^-1(i, j).
        double v = 0.0;
        for (const auto& [i, gi] : g.row(static_cast<size_t>(k)))
          for (const auto& [j, gj] : g.row(static_cast<size_t>(l))) v += std::real(std::conj(gi) * gj) * cache->At(i, j);
        s(k, l) = v;
      } else {
        Complex v = 0.0;
        for (const auto& [i, gi] : g.row(static_cast<size_t>(k)))
          for (const auto& [j, gj] : g.row(static_cast<size_t>(l))) v += std::conj(gi) * gj * cache->At(i, j);
        s(k, l) = std::real(v);
      }
    }
  }
  constexpr int kTile = 32;
  for (int l0 = 0; l0 < r; l0 += kTile)
    for (int k0 = l0; k0 < r; k0 += kTile)
      for (int l = l0; l < std::min(l0 + kTile, r); ++l)
        for (int k = std::max(k0, l + 1); k < std::min(k0 + kTile, r); ++k) s(k, l) = s(l, k);
  cache->terms = terms;
  cache->g = std::move(g);
  cache->s = std::move(s);
}

// The agent's block for one step, from `cache` (AgentMatrix filled it for these rows), and
// each row's value without rows, which follows y0 and the map's constants.
template <typename MapFn, typename Scalar>
void AgentBlock(MapFn map, const InverseBlock<Scalar>& cache, AgentRows* ar) {
  ar->g = &cache.g;
  ar->s = &cache.s;
  const int r = static_cast<int>(ar->rows.size());
  ar->base.assign(static_cast<size_t>(r), 0.0);
  for (int k = 0; k < r; ++k) {
    for (const auto& [i, c] : ar->terms.row(static_cast<size_t>(k)))
      ar->base[static_cast<size_t>(k)] += std::real(std::conj(c) * map(i).k);
    for (const auto& [j, gj] : ar->g->row(static_cast<size_t>(k)))
      ar->base[static_cast<size_t>(k)] += std::real(std::conj(gj) * ar->y0[j]);
  }
}

// The agent's unknowns under the row forces: y0 + K^-1 G lambda.
template <typename Solver>
Eigen::VectorXcd AgentResponse(const Solver& solver, const AgentRows& ar, const Eigen::VectorXd& forces) {
  Eigen::VectorXcd rhs = Eigen::VectorXcd::Zero(ar.y0.size());
  for (size_t k = 0; k < ar.rows.size(); ++k)
    for (const auto& [j, gj] : ar.g->row(k)) rhs[j] += gj * forces[ar.rows[k]];
  return ar.y0 + solver.Solve(rhs).col(0);
}

// Where a row sits in the agents' blocks.
struct RowSlot {
  int agent;  // index into the involved agents
  int local;  // index of the row in that agent's block
};

// The slots of every row, stored one row after another.
struct RowSlots {
  struct Span {
    const RowSlot *first, *last;
    const RowSlot* begin() const { return first; }
    const RowSlot* end() const { return last; }
  };
  std::vector<int> start;  // #R+1 offsets into items
  std::vector<RowSlot> items;

  Span row(int r) const {
    return {items.data() + start[static_cast<size_t>(r)], items.data() + start[static_cast<size_t>(r) + 1]};
  }
};

// Projected Gauss-Seidel on the rows from `forces`: S lambda is kept up to date as forces
// change, as each agent's part u = S_a lambda_a (a row's value is the sum of its agents'
// parts), so a force change is one contiguous column update per agent. Returns the
// sweeps used (0 without one-sided rows, which need none).
//
// A row is only worked out again when it may have something to do. S_a is positive
// semidefinite, so |S_a(l, c)| <= sqrt(S_a(l, l) S_a(c, c)): a force change delta on
// column c moves any u_a(l) by at most sqrt(S_a(l, l)) sqrt(S_a(c, c)) |delta|. Each agent
// sums sqrt(S_a(c, c)) |delta| over its changes (`moved`); a row keeps its residual from
// when it was last worked out, and while that residual, grown by what its agents moved
// since, leaves it within the tolerance (or, a one-sided row without force, pulling), the
// row would change nothing and is passed over: the same forces as visiting every row.
//
// With `side` (per block, 0 or 1: SplitInTwo), a sweep visits the rows of side 0's agents,
// those of side 1's, then the rows between the sides, each in time order. The first two
// touch no agent in common, so they run on two threads (`threads`) with the same result as
// one after the other: the forces do not depend on the thread count.
int SweepRows(const std::vector<AgentRows*>& blocks, const RowSlots& slots, const SeparationRows& in,
              const SeparationSettings& settings, const Eigen::VectorXd& q, const Eigen::VectorXd& diag,
              const std::vector<char>& side, int threads, Eigen::VectorXd& forces, bool* converged, int64_t* updates) {
  const int nr = static_cast<int>(in.rhs.size());
  auto unilateral = [&](int r) { return in.kind.size() && in.kind[r] != 0; };
  *converged = false;
  bool any_unilateral = false;
  for (int r = 0; r < nr; ++r) any_unilateral = any_unilateral || unilateral(r);
  if (!any_unilateral) {
    *converged = true;
    return 0;
  }
  const size_t nq = blocks.size();
  // The rows a sweep visits, in that order: side 0's, side 1's, those between (or all).
  std::vector<int> order[3];
  for (int r = 0; r < nr; ++r) {
    if (!(diag[r] > 0.0)) continue;
    int group = 0;
    if (!side.empty()) {
      group = side[static_cast<size_t>(slots.items[static_cast<size_t>(slots.start[static_cast<size_t>(r)])].agent)];
      for (int i = slots.start[static_cast<size_t>(r)] + 1; i < slots.start[static_cast<size_t>(r) + 1]; ++i)
        if (side[static_cast<size_t>(slots.items[static_cast<size_t>(i)].agent)] != group) group = 2;
    }
    order[group].push_back(r);
  }
  // What the two threads write lies apart: each agent's sum of moves (`moved`) and its part
  // u = S_a lambda_a of the row values, side 0's agents first, then (a cache line on) side 1's;
  // and each group's rows' forces, residuals and slots in arrays of the group's own.
  constexpr size_t kLine = 8;  // doubles per cache line
  std::vector<size_t> place(nq);  // per agent: its index in `moved`
  std::vector<Eigen::Index> offset(nq);  // per agent: where its part of u starts
  size_t places = 0;
  Eigen::Index length = 0;
  for (int s_ = 0; s_ < 2; ++s_) {
    for (size_t b = 0; b < nq; ++b)
      if ((side.empty() ? 0 : side[b]) == s_) {
        place[b] = places++;
        offset[b] = length;
        length += static_cast<Eigen::Index>(blocks[b]->rows.size());
      }
    places += kLine;
    length += static_cast<Eigen::Index>(kLine);
  }
  Eigen::VectorXd u = Eigen::VectorXd::Zero(length);
  for (size_t b = 0; b < nq; ++b) {
    const AgentRows* ar = blocks[b];
    Eigen::VectorXd f(static_cast<Eigen::Index>(ar->rows.size()));
    for (size_t k = 0; k < ar->rows.size(); ++k) f[static_cast<Eigen::Index>(k)] = forces[ar->rows[k]];
    const Eigen::VectorXd ub = *ar->s * f;
    u.segment(offset[b], ub.size()) = ub;
  }
  std::vector<double> moved(places, 0.0);
  // Per slot of a group's rows (in the rows' order): its agent's part of u, its column of S_a,
  // its entry of u, its agent's place in `moved`, sqrt of the row's diagonal entry in that
  // agent's block, and the agent's `moved` when the row was last worked out.
  struct Slot {
    double* part;
    const double* column;
    Eigen::Index length;
    Eigen::Index entry;
    size_t mover;
    double root;
    double then;
  };
  struct Group {
    std::vector<int> rows;
    std::vector<int> start;       // per row of the group, into `slot`
    std::vector<Slot> slot;
    std::vector<double> force, residual;
    std::vector<char> known;
  };
  Group groups[3];
  for (int k = 0; k < 3; ++k) {
    Group& gr = groups[k];
    gr.rows = std::move(order[k]);
    gr.start.assign(1, 0);
    for (int r : gr.rows) {
      for (int i = slots.start[static_cast<size_t>(r)]; i < slots.start[static_cast<size_t>(r) + 1]; ++i) {
        const RowSlot& sl = slots.items[static_cast<size_t>(i)];
        const size_t b = static_cast<size_t>(sl.agent);
        const Eigen::MatrixXd& sa = *blocks[b]->s;
        gr.slot.push_back({u.data() + offset[b], sa.data() + static_cast<Eigen::Index>(sl.local) * sa.rows(), sa.rows(),
                           offset[b] + sl.local, place[b], std::sqrt(std::max(sa(sl.local, sl.local), 0.0)), 0.0});
      }
      gr.start.push_back(static_cast<int>(gr.slot.size()));
      gr.force.push_back(forces[r]);
    }
    gr.residual.assign(gr.rows.size(), 0.0);
    gr.known.assign(gr.rows.size(), 0);
  }
  const double relax = settings.relaxation, tol = settings.tolerance;
  // Rows ahead whose entries of u and columns of S are fetched early (memory latency).
  constexpr int kAhead = 8;
  // One pass over a group's rows; returns the largest change passed on, counts the updates.
  auto pass = [&](Group& gr, int64_t* count) {
    double change = 0.0;
    const int n = static_cast<int>(gr.rows.size());
    for (int p = 0; p < n; ++p) {
      const int r = gr.rows[static_cast<size_t>(p)];
      Slot* const s0 = gr.slot.data() + gr.start[static_cast<size_t>(p)];
      Slot* const s1 = gr.slot.data() + gr.start[static_cast<size_t>(p) + 1];
      if (p + kAhead < n)
        for (const Slot* a = gr.slot.data() + gr.start[static_cast<size_t>(p + kAhead)],
                        *end = gr.slot.data() + gr.start[static_cast<size_t>(p + kAhead) + 1];
             a < end; ++a) {
          __builtin_prefetch(u.data() + a->entry);
          __builtin_prefetch(a->column);
        }
      double& force = gr.force[static_cast<size_t>(p)];
      double& residual = gr.residual[static_cast<size_t>(p)];
      if (gr.known[static_cast<size_t>(p)]) {
        double reach = 0.0;
        for (const Slot* sl = s0; sl < s1; ++sl) reach += sl->root * (moved[sl->mover] - sl->then);
        const double res = residual;
        // Far above the rounding of the values compared, far below the tolerance.
        const double margin = 1e-9 * (tol + std::abs(q[r]) + std::abs(res) + reach);
        const bool idle = unilateral(r) && force == 0.0 ? relax * (res + reach) <= tol - margin
                                                        : relax * (std::abs(res) + reach) <= tol - margin;
        if (idle) continue;
      }
      double value = 0.0;
      for (const Slot* sl = s0; sl < s1; ++sl) value += u[sl->entry];
      const double res = q[r] - value - in.softness[r] * force;
      double f = force + relax * res / diag[r];
      if (unilateral(r)) f = std::max(f, 0.0);
      const double delta = f - force;
      gr.known[static_cast<size_t>(p)] = 1;
      // A change below the tolerance is not worth passing on to the other rows.
      if (std::abs(delta) * diag[r] <= tol) {
        residual = res;
        for (Slot* sl = s0; sl < s1; ++sl) sl->then = moved[sl->mover];
        continue;
      }
      force = f;
      ++*count;
      change = std::max(change, std::abs(delta) * diag[r]);
      for (const Slot* sl = s0; sl < s1; ++sl) {
        Eigen::Map<Eigen::VectorXd>(sl->part, sl->length).noalias() +=
            Eigen::Map<const Eigen::VectorXd>(sl->column, sl->length) * delta;
        moved[sl->mover] += sl->root * std::abs(delta);
      }
      residual = res - diag[r] * delta;
      for (Slot* sl = s0; sl < s1; ++sl) sl->then = moved[sl->mover];
    }
    return change;
  };
  const bool two = threads > 1 && !groups[0].rows.empty() && !groups[1].rows.empty();
  int sweep = 0;
  for (sweep = 1; sweep <= settings.max_sweeps; ++sweep) {
    double change[3] = {0.0, 0.0, 0.0};
    int64_t count[3] = {0, 0, 0};
    if (two)
      OnTwoThreads([&] { change[0] = pass(groups[0], &count[0]); }, [&] { change[1] = pass(groups[1], &count[1]); });
    else
      for (int k = 0; k < 2; ++k) change[k] = pass(groups[k], &count[k]);
    change[2] = pass(groups[2], &count[2]);
    *updates += count[0] + count[1] + count[2];
    if (std::max({change[0], change[1], change[2]}) <= tol) {
      *converged = true;
      break;
    }
  }
  for (const Group& gr : groups)
    for (size_t p = 0; p < gr.rows.size(); ++p) forces[gr.rows[p]] = gr.force[p];
  return std::min(sweep, settings.max_sweeps);
}

// The involved agents in two sides for SweepRows (0 or 1 each), or none (empty) below
// `from` frames (`work`; or `from` negative): a line across the crowd's ground, across its longer extent, with about as
// many rows' slots on either side (agents by the centroid of the rest frames their rows
// touch; ties by agent). It depends on the rows alone, not on the threads.
std::vector<char> SplitInTwo(const SeparationState& data, const std::vector<int>& involved,
                             const std::vector<AgentRows*>& blocks, int64_t work, int64_t from) {
  const size_t nq = involved.size();
  if (from < 0 || work < from || nq < 2) return {};
  std::vector<Eigen::Vector2d> centre(nq, Eigen::Vector2d::Zero());
  for (size_t q = 0; q < nq; ++q) {
    const Agent& ag = data.agents[static_cast<size_t>(involved[q])];
    const RowLists& terms = blocks[q]->terms;
    for (const auto& item : terms.items)
      centre[q] += data.rest.row(ag.first + item.first).transpose();
    centre[q] /= static_cast<double>(std::max<size_t>(terms.items.size(), 1));
  }
  Eigen::Vector2d lo = centre[0], hi = centre[0];
  for (const auto& c : centre) {
    lo = lo.cwiseMin(c);
    hi = hi.cwiseMax(c);
  }
  const int axis = (hi - lo)[0] >= (hi - lo)[1] ? 0 : 1;
  std::vector<int> by(nq);
  for (size_t q = 0; q < nq; ++q) by[q] = static_cast<int>(q);
  std::sort(by.begin(), by.end(), [&](int a, int b) {
    const double ca = centre[static_cast<size_t>(a)][axis], cb = centre[static_cast<size_t>(b)][axis];
    return ca < cb || (ca == cb && a < b);
  });
  int64_t total = 0;
  for (const AgentRows* ar : blocks) total += static_cast<int64_t>(ar->rows.size());
  std::vector<char> side(nq, 1);
  int64_t sum = 0;
  for (int q : by) {
    if (2 * sum >= total) break;
    side[static_cast<size_t>(q)] = 0;
    sum += static_cast<int64_t>(blocks[static_cast<size_t>(q)]->rows.size());
  }
  return side;
}

// Equality rows exactly for the one-sided forces found: (S_EE + D_E) lambda_E = q_E -
// S_EU lambda_U.
void SolveEqualities(const std::vector<AgentRows*>& blocks, const SeparationRows& in, const Eigen::VectorXd& q,
                     Eigen::VectorXd& forces, bool* regularized) {
  const int nr = static_cast<int>(in.rhs.size());
  auto unilateral = [&](int r) { return in.kind.size() && in.kind[r] != 0; };
  std::vector<int> eq_index(static_cast<size_t>(nr), -1);
  std::vector<int> eq_rows;
  for (int r = 0; r < nr; ++r)
    if (!unilateral(r)) {
      eq_index[static_cast<size_t>(r)] = static_cast<int>(eq_rows.size());
      eq_rows.push_back(r);
    }
  const int ne = static_cast<int>(eq_rows.size());
  if (ne == 0) return;
  Eigen::VectorXd rhs(ne);
  std::vector<Eigen::Triplet<double>> trip;
  for (int e = 0; e < ne; ++e) {
    rhs[e] = q[eq_rows[static_cast<size_t>(e)]];
    trip.emplace_back(e, e, in.softness[eq_rows[static_cast<size_t>(e)]]);
  }
  for (const AgentRows* ar : blocks)
    for (size_t k = 0; k < ar->rows.size(); ++k) {
      const int ek = eq_index[static_cast<size_t>(ar->rows[k])];
      if (ek < 0) continue;
      for (size_t l = 0; l < ar->rows.size(); ++l) {
        const double skl = (*ar->s)(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(l));
        const int el = eq_index[static_cast<size_t>(ar->rows[l])];
        if (el >= 0)
          trip.emplace_back(ek, el, skl);
        else
          rhs[ek] -= skl * forces[ar->rows[l]];
      }
    }
  Eigen::SparseMatrix<double> see(ne, ne);
  see.setFromTriplets(trip.begin(), trip.end());
  double largest = 0.0;
  for (int e = 0; e < ne; ++e) largest = std::max(largest, see.coeff(e, e));
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt(see);
  const bool dependent = ldlt.info() != Eigen::Success ||
                         (ne && ldlt.vectorD().minCoeff() <= 1e-13 * std::max(largest, 1e-300));
  if (dependent) {
    // Hard rows that repeat or contradict each other: as nearly hard as arithmetic allows.
    *regularized = true;
    for (int e = 0; e < ne; ++e) see.coeffRef(e, e) += 1e-10 * std::max(largest, 1e-300);
    ldlt.compute(see);
    if (ldlt.info() != Eigen::Success) throw NumericalError(kWhere, "the equality rows could not be solved");
  }
  const Eigen::VectorXd fe = ldlt.solve(rhs);
  for (int e = 0; e < ne; ++e) forces[eq_rows[static_cast<size_t>(e)]] = fe[e];
}

// Solves the mixed complementarity problem on the Schur complement,
//   (S + D) lambda = q              on equality rows,
//   lambda >= 0, (S + D) lambda - q >= 0, complementary   on "at least" rows,
// by projected Gauss-Seidel from `forces`, then meets the equality rows exactly for the
// unilateral forces found. Returns the sweeps used.
int SolveRows(const std::vector<AgentRows*>& blocks, const RowSlots& slots,
              const SeparationRows& in, const SeparationSettings& settings, const std::vector<char>& side,
              int threads, Eigen::VectorXd& forces, bool* regularized, bool* converged, int64_t* updates) {
  const int nr = static_cast<int>(in.rhs.size());
  Eigen::VectorXd q = in.rhs;
  Eigen::VectorXd diag = in.softness;
  for (int r = 0; r < nr; ++r)
    for (const RowSlot& sl : slots.row(r)) {
      q[r] -= blocks[static_cast<size_t>(sl.agent)]->base[static_cast<size_t>(sl.local)];
      diag[r] += (*blocks[static_cast<size_t>(sl.agent)]->s)(sl.local, sl.local);
    }
  for (int r = 0; r < nr; ++r)
    if (in.kind.size() && in.kind[r] != 0) forces[r] = std::max(forces[r], 0.0);
  const int sweeps = SweepRows(blocks, slots, in, settings, q, diag, side, threads, forces, converged, updates);
  SolveEqualities(blocks, in, q, forces, regularized);
  return sweeps;
}

}  // namespace
}  // namespace detail

struct SeparationCache {
  std::vector<detail::InverseBlock<detail::Complex>> step1;
  std::vector<detail::InverseBlock<double>> step2;
};

namespace detail {
namespace {

// The rows of one solve gathered by agent: each involved agent's rows and terms (blocks),
// and where each row sits in its agents' blocks (slots).
struct Gathered {
  std::vector<AgentRows> agent_rows;
  std::vector<int> involved;          // agents some row touches
  std::vector<AgentRows*> blocks;     // their rows, in the order of `involved`
  RowSlots slots;
};

void ValidateRows(const SeparationState& data, const SeparationRows& in, const SeparationSettings& settings) {
  const Eigen::Index nr = in.rhs.size(), nt = in.term_row.size();
  const Eigen::Index nv = data.rest.rows();
  if (in.direction.rows() != nr || in.softness.size() != nr || in.term_vertex.size() != nt ||
      in.term_weight.size() != nt || (in.kind.size() && in.kind.size() != nr) ||
      (in.initial_forces.size() && in.initial_forces.size() != nr) ||
      (in.initial_shape_forces.size() && in.initial_shape_forces.size() != nr))
    throw InvalidInput(kWhere, "direction, rhs, softness, kind and initial forces need one entry "
                               "per row; term_row, term_vertex and term_weight one per term");
  if (!in.direction.allFinite() || !in.rhs.allFinite() || !in.term_weight.allFinite() || !in.softness.allFinite() ||
      !in.initial_forces.allFinite() || !in.initial_shape_forces.allFinite())
    throw InvalidInput(kWhere, "rows must be finite");
  if (nr && in.softness.minCoeff() < 0.0) throw InvalidInput(kWhere, "softness must not be negative");
  if (!(settings.tolerance > 0.0) || settings.max_sweeps < 1 || !(settings.relaxation > 0.0 && settings.relaxation < 2.0))
    throw InvalidInput(kWhere, "tolerance must be positive, max_sweeps at least 1 and relaxation in (0, 2)");
  std::vector<char> has_term(static_cast<size_t>(nr), 0);
  for (Eigen::Index t = 0; t < nt; ++t) {
    if (in.term_row[t] < 0 || in.term_row[t] >= nr) throw InvalidInput(kWhere, "term row out of range");
    if (in.term_vertex[t] < 0 || in.term_vertex[t] >= nv) throw InvalidInput(kWhere, "term vertex out of range");
    if (in.term_weight[t] != 0.0) has_term[static_cast<size_t>(in.term_row[t])] = 1;
  }
  for (Eigen::Index r = 0; r < nr; ++r)
    if (!has_term[static_cast<size_t>(r)]) throw InvalidInput(kWhere, "row " + std::to_string(r) + " has no term");
}

// Terms by agent (in term order within a row); rows numbered locally per agent.
void GatherAgentRows(const SeparationState& data, const SeparationRows& in, std::vector<AgentRows>& agent_rows) {
  const Eigen::Index nt = in.term_row.size();
  const size_t na = data.agents.size();
  agent_rows.assign(na, AgentRows());
  std::vector<int> count(na, 0), agent_of_term(static_cast<size_t>(nt), -1);
  for (Eigen::Index t = 0; t < nt; ++t) {
    if (in.term_weight[t] == 0.0) continue;  // an interpolation weight of zero touches nothing
    agent_of_term[static_cast<size_t>(t)] = data.agent_of[static_cast<size_t>(in.term_vertex[t])];
    ++count[static_cast<size_t>(agent_of_term[static_cast<size_t>(t)])];
  }
  std::vector<std::vector<std::pair<int, Eigen::Index>>> by_agent(na);  // (row, term)
  for (size_t a = 0; a < na; ++a) by_agent[a].reserve(static_cast<size_t>(count[a]));
  for (Eigen::Index t = 0; t < nt; ++t)
    if (agent_of_term[static_cast<size_t>(t)] >= 0)
      by_agent[static_cast<size_t>(agent_of_term[static_cast<size_t>(t)])].emplace_back(in.term_row[t], t);
  for (size_t a = 0; a < na; ++a) {
    auto& list = by_agent[a];
    if (list.empty()) continue;
    if (!std::is_sorted(list.begin(), list.end())) std::stable_sort(list.begin(), list.end());
    AgentRows& ar = agent_rows[a];
    ar.terms.items.reserve(list.size());
    for (size_t i = 0; i < list.size(); ++i) {
      const auto [row, t] = list[i];
      if (i > 0 && row != list[i - 1].first) ar.terms.CloseRow();
      if (i == 0 || row != list[i - 1].first) ar.rows.push_back(row);
      const Complex dir(in.direction(row, 0), in.direction(row, 1));
      ar.terms.items.emplace_back(in.term_vertex[t] - data.agents[a].first, in.term_weight[t] * dir);
    }
    ar.terms.CloseRow();
  }
}

void Gather(const SeparationState& data, const SeparationRows& in, Gathered& g) {
  GatherAgentRows(data, in, g.agent_rows);
  for (size_t a = 0; a < g.agent_rows.size(); ++a)
    if (!g.agent_rows[a].rows.empty()) {
      g.involved.push_back(static_cast<int>(a));
      g.blocks.push_back(&g.agent_rows[a]);
    }
  const int nr = static_cast<int>(in.rhs.size());
  const int nq = static_cast<int>(g.involved.size());
  RowSlots& slots = g.slots;
  slots.start.assign(static_cast<size_t>(nr) + 1, 0);
  for (int q = 0; q < nq; ++q)
    for (int row : g.blocks[static_cast<size_t>(q)]->rows) ++slots.start[static_cast<size_t>(row) + 1];
  for (int r = 0; r < nr; ++r) slots.start[static_cast<size_t>(r) + 1] += slots.start[static_cast<size_t>(r)];
  slots.items.resize(static_cast<size_t>(slots.start[static_cast<size_t>(nr)]));
  std::vector<int> fill(slots.start.begin(), slots.start.end() - 1);
  for (int q = 0; q < nq; ++q) {
    const std::vector<int>& rows = g.blocks[static_cast<size_t>(q)]->rows;
    for (size_t k = 0; k < rows.size(); ++k)
      slots.items[static_cast<size_t>(fill[static_cast<size_t>(rows[k])]++)] = {q, static_cast<int>(k)};
  }
}

// After step 1's forces: each involved agent's step-1 positions into result.shape, its
// ranges' turns, and its step-2 block (edges at rest length along step 1's directions).
void ScaleBlocks(const SeparationState& data, const Gathered& g, int threads, SeparationCache& cache,
                 std::vector<std::vector<Complex>>& turns, SeparationResult& result) {
  const int nq = static_cast<int>(g.involved.size());
  turns.assign(static_cast<size_t>(nq), {});
  ParallelFor(nq, threads, [&](int q) {
    const Agent& ag = data.agents[static_cast<size_t>(g.involved[static_cast<size_t>(q)])];
    AgentRows* ar = g.blocks[static_cast<size_t>(q)];
    const Eigen::VectorXcd y1 = AgentResponse(ag.step1, *ar, result.shape_forces);
    std::vector<Complex> z1(static_cast<size_t>(ag.count));
    for (int i = 0; i < ag.count; ++i) {
      const Map m = ag.Map1(i);
      z1[static_cast<size_t>(i)] = m.a0 * y1[m.j0] + (m.j1 >= 0 ? m.a1 * y1[m.j1] : Complex(0.0)) + m.k;
      result.shape(ag.first + i, 0) = z1[static_cast<size_t>(i)].real();
      result.shape(ag.first + i, 1) = z1[static_cast<size_t>(i)].imag();
    }
    auto& turn = turns[static_cast<size_t>(q)];
    std::vector<Complex> edges;
    data.Step2Targets(ag, y1, z1, edges, turn);
    ar->y0 = ag.step2.Solve(data.Step2Rhs(ag, edges, turn)).col(0);
    AgentBlock([&](int i) { return ag.Map2(i, turn); }, cache.step2[static_cast<size_t>(g.involved[static_cast<size_t>(q)])],
               ar);
  });
}

// Step 2's G and S of the involved agents, taken in turn from `next` (shared by the threads
// that work on them): they depend on the rows' terms alone, not on step 1's result.
void Step2Matrices(const SeparationState& data, const Gathered& g, SeparationCache& cache, std::atomic<int>& next) {
  const int nq = static_cast<int>(g.involved.size());
  for (int q = next++; q < nq; q = next++) {
    const int a = g.involved[static_cast<size_t>(q)];
    const Agent& ag = data.agents[static_cast<size_t>(a)];
    const std::vector<Complex> turn(ag.ranges.size(), 1.0);  // G does not depend on the turns
    AgentMatrix(ag.step2, ag.n2, [&](int i) { return ag.Map2(i, turn); }, g.blocks[static_cast<size_t>(q)]->terms,
                &cache.step2[static_cast<size_t>(a)]);
  }
}

// After step 2's forces: every involved agent's positions and range angles, then each
// row's residual.
void FinalPositions(const SeparationState& data, const SeparationRows& in, const Gathered& g, int threads,
                    const std::vector<std::vector<Complex>>& turns, SeparationResult& result) {
  const int nq = static_cast<int>(g.involved.size());
  ParallelFor(nq, threads, [&](int q) {
    const Agent& ag = data.agents[static_cast<size_t>(g.involved[static_cast<size_t>(q)])];
    const Eigen::VectorXcd y2 = AgentResponse(ag.step2, *g.blocks[static_cast<size_t>(q)], result.forces);
    const auto& turn = turns[static_cast<size_t>(q)];
    for (int i = 0; i < ag.count; ++i) {
      const Map m = ag.Map2(i, turn);
      const Complex z = m.a0 * y2[m.j0] + m.k;
      result.positions(ag.first + i, 0) = z.real();
      result.positions(ag.first + i, 1) = z.imag();
    }
    for (size_t k = 0; k < ag.ranges.size(); ++k) result.rigid_angles[ag.global_range[k]] = std::arg(turn[k]);
  });
  for (Eigen::Index t = 0; t < in.term_row.size(); ++t) {
    const int r = in.term_row[t], v = in.term_vertex[t];
    result.residuals[r] += in.term_weight[t] * (in.direction(r, 0) * result.positions(v, 0) +
                                                in.direction(r, 1) * result.positions(v, 1));
  }
  result.residuals -= in.rhs;
}

int64_t CachedColumns(const SeparationCache& cache) {
  int64_t columns = 0;
  for (size_t a = 0; a < cache.step1.size(); ++a) columns += cache.step1[a].columns + cache.step2[a].columns;
  return columns;
}

}  // namespace
}  // namespace detail

void SeparationCacheDeleter::operator()(SeparationCache* cache) const { delete cache; }

std::unique_ptr<SeparationCache, SeparationCacheDeleter> SeparationNewCache() {
  return std::unique_ptr<SeparationCache, SeparationCacheDeleter>(new SeparationCache());
}

void SeparationSolve(const SeparationData& handle, const SeparationRows& in, const SeparationSettings& settings,
                     SeparationCache& cache, SeparationResult& result) {
  using namespace detail;
  Require(handle.state != nullptr, kWhere, "the data was not precomputed");
  const SeparationState& data = *handle.state;
  result.seconds.setZero();
  double clock = Seconds();
  auto lap = [&](int phase) {
    const double now = Seconds();
    result.seconds[phase] += now - clock;
    clock = now;
  };
  if (cache.step1.size() != data.agents.size()) {
    cache.step1.assign(data.agents.size(), InverseBlock<Complex>());
    cache.step2.assign(data.agents.size(), InverseBlock<double>());
  }
  ValidateRows(data, in, settings);
  const Eigen::Index nr = in.rhs.size();
  Gathered g;
  Gather(data, in, g);
  const int nq = static_cast<int>(g.involved.size());

  result.positions = data.rest;
  result.shape = data.rest;
  result.rigid_angles = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(data.rigid.size()));
  result.moved_agents = nq;
  result.regularized = false;
  result.converged = true;
  result.sweeps = 0;
  result.updates = 0;
  const int64_t columns_before = CachedColumns(cache);
  result.shape_forces = in.initial_shape_forces.size() ? in.initial_shape_forces
                        : in.initial_forces.size()     ? in.initial_forces
                                                       : Eigen::VectorXd::Zero(nr);
  result.forces = result.shape_forces;
  result.residuals = Eigen::VectorXd::Zero(nr);
  if (nr == 0) return;
  int64_t work = 0;
  for (int a : g.involved) work += data.agents[static_cast<size_t>(a)].count;
  const int threads = work < 20000 ? 1 : data.threads;
  const std::vector<char> side = SplitInTwo(data, g.involved, g.blocks, work, settings.split_from);

  // Step 1.
  lap(3);
  ParallelFor(nq, threads, [&](int q) {
    const Agent& ag = data.agents[static_cast<size_t>(g.involved[static_cast<size_t>(q)])];
    AgentRows* ar = g.blocks[static_cast<size_t>(q)];
    ar->y0 = ag.y1_rest;
    auto& step1 = cache.step1[static_cast<size_t>(g.involved[static_cast<size_t>(q)])];
    const auto map = [&](int i) { return ag.Map1(i); };
    AgentMatrix(ag.step1, ag.n1, map, ar->terms, &step1);
    AgentBlock(map, step1, ar);
  });
  bool converged = true;
  lap(0);
  // Step 2's blocks (they depend on the rows alone), then step 1's forces, each on every
  // thread; without the split, step 1's forces on one thread while the other forms the blocks.
  std::atomic<int> next{0};
  if (side.empty()) {
    double sweeps_end = 0.0;
    auto step1_rows = [&] {
      result.sweeps = SolveRows(g.blocks, g.slots, in, settings, side, 1, result.shape_forces, &result.regularized,
                                &converged, &result.updates);
      sweeps_end = Seconds();
      Step2Matrices(data, g, cache, next);
    };
    if (threads > 1)
      OnTwoThreads(step1_rows, [&] { Step2Matrices(data, g, cache, next); });
    else
      step1_rows();
    result.seconds[1] += sweeps_end - clock;
    clock = sweeps_end;
    lap(0);
  } else {
    if (threads > 1)
      OnTwoThreads([&] { Step2Matrices(data, g, cache, next); }, [&] { Step2Matrices(data, g, cache, next); });
    else
      Step2Matrices(data, g, cache, next);
    lap(0);
    result.sweeps = SolveRows(g.blocks, g.slots, in, settings, side, threads, result.shape_forces, &result.regularized,
                              &converged, &result.updates);
    lap(1);
  }
  if (in.initial_shape_forces.size() && in.initial_forces.size()) result.forces = in.initial_forces;
  else result.forces = result.shape_forces;
  result.converged = converged;

  // Step 1's result turns each range and each step; step 2 restores the rest lengths.
  std::vector<std::vector<Complex>> turns;
  ScaleBlocks(data, g, threads, cache, turns, result);
  lap(0);
  result.sweeps += SolveRows(g.blocks, g.slots, in, settings, side, threads, result.forces, &result.regularized, &converged,
                             &result.updates);
  lap(1);
  result.converged = result.converged && converged;
  FinalPositions(data, in, g, threads, turns, result);
  result.inverse_columns = CachedColumns(cache) - columns_before;
  lap(2);
}

void SeparationSolve(const SeparationData& data, const SeparationRows& in, const SeparationSettings& settings,
                     SeparationResult& result) {
  SeparationCache cache;
  SeparationSolve(data, in, settings, cache, result);
}

}  // namespace mocapedit
