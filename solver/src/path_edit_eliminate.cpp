// Elimination of hard constraints (path_edit_internal.h): vertices tied by hard links and
// rigid ranges share one unknown up to known offsets, a hard handle fixes that unknown,
// and in step 1 the vertices of a rotating range follow its two masters.
#include "path_edit_internal.h"

namespace mocapedit::detail {
namespace {

// Similarity dependents: every vertex of a (non-degenerate) rotating range but its masters
// (step 1 only). Returns a flag per vertex.
std::vector<char> SimilarityDependents(const PathEditState& d, bool step1, Elimination& e) {
  std::vector<char> dependent(d.vertices, 0);
  if (!step1) return dependent;
  for (size_t r = 0; r < d.rigid.size(); ++r) {
    if (d.rigid[r].mode != RigidMode::kRotate || d.degenerate[r]) continue;
    const LCplx z1 = d.zl(d.master1[r]), z2 = d.zl(d.master2[r]);
    for (int v : d.rigid[r].vertices) {
      if (v == d.master1[r] || v == d.master2[r]) continue;
      dependent[v] = 1;
      e.dep_vertex.push_back(v);
      e.dep_m1.push_back(d.master1[r]);
      e.dep_m2.push_back(d.master2[r]);
      e.dep_gamma.push_back((d.zl(v) - z1) / (z2 - z1));
    }
  }
  return dependent;
}

// Hard links, and the ties of every vertex of a rigid range to its first master (in step 1
// only for ranges that translate).
void CollectTies(const PathEditState& d, bool step1, Elimination& e) {
  for (Eigen::Index l = 0; l < d.links.rows(); ++l)
    if (d.link_weights[l] == kInf)
      e.ties.push_back({d.links(l, 0), d.links(l, 1), TieKind::kLink, static_cast<int>(l), {}});
  for (size_t r = 0; r < d.rigid.size(); ++r) {
    const RigidRange& range = d.rigid[r];
    const bool translate = range.mode == RigidMode::kTranslate || (step1 && d.degenerate[r]);
    if (step1 && !translate) continue;
    const int m = d.master1[r];
    for (int v : range.vertices)
      if (v != m)
        e.ties.push_back({v, m, translate ? TieKind::kRest : TieKind::kRotated, static_cast<int>(r),
                          d.zl(v) - d.zl(m)});
  }
}

// Spanning forest of the ties, breadth first, roots in vertex order (deterministic); the
// ties left out close cycles (extra_ties).
void SpanningForest(int n, const std::vector<char>& dependent, Elimination& e) {
  // Ties at each vertex, CSR.
  std::vector<int> adj_ptr(n + 1, 0), adj(2 * e.ties.size());
  for (const Tie& t : e.ties) ++adj_ptr[t.a + 1], ++adj_ptr[t.b + 1];
  for (int v = 0; v < n; ++v) adj_ptr[v + 1] += adj_ptr[v];
  {
    std::vector<int> at(adj_ptr.begin(), adj_ptr.end() - 1);
    for (size_t t = 0; t < e.ties.size(); ++t) {
      adj[at[e.ties[t].a]++] = static_cast<int>(t);
      adj[at[e.ties[t].b]++] = static_cast<int>(t);
    }
  }
  e.parent.assign(n, -1);
  e.parent_tie.assign(n, -1);
  e.depth.assign(n, 0);
  std::vector<char> seen(n, 0), tree_tie(e.ties.size(), 0);
  e.order.resize(n);
  size_t members = 0;  // written to order
  for (int s = 0; s < n; ++s) {
    if (dependent[s]) {
      e.root[s] = -1;
      continue;
    }
    if (seen[s]) continue;
    seen[s] = 1;
    size_t head = members;
    e.order[members++] = s;
    e.root[s] = s;
    while (head < members) {
      const int v = e.order[head++];
      for (int k = adj_ptr[v]; k < adj_ptr[v + 1]; ++k) {
        const int t = adj[k];
        const int w = e.ties[t].a == v ? e.ties[t].b : e.ties[t].a;
        if (seen[w]) continue;
        seen[w] = 1;
        tree_tie[t] = 1;
        e.parent[w] = v;
        e.parent_tie[w] = t;
        e.depth[w] = e.depth[v] + 1;
        e.root[w] = s;
        e.order[members++] = w;
      }
    }
  }
  e.order.resize(members);
  for (size_t t = 0; t < e.ties.size(); ++t)
    if (!tree_tie[t]) e.extra_ties.push_back(static_cast<int>(t));
}

// Hard handles fix their class; the free classes get columns in root (vertex) order,
// which keeps a chain banded.
void NumberColumns(const PathEditState& d, int n, Elimination& e) {
  e.fix_handle.assign(n, -1);
  for (Eigen::Index h = 0; h < d.handles.size(); ++h) {
    if (d.handle_weights[h] != kInf) continue;
    const int r = e.root[d.handles[h]];
    if (e.fix_handle[r] < 0)
      e.fix_handle[r] = static_cast<int>(h);
    else
      e.extra_handles.push_back(static_cast<int>(h));
  }
  e.col.assign(n, -1);
  e.columns = 0;
  for (int v = 0; v < n; ++v)
    if (e.root[v] == v && e.fix_handle[v] < 0) e.col[v] = e.columns++;
  // Plain vertices: a class of one free vertex.
  std::vector<int> size(n, 0);
  for (int v : e.order) ++size[e.root[v]];
  e.plain_col.assign(n, -1);
  for (int v : e.order)
    if (e.root[v] == v && size[v] == 1 && e.fix_handle[v] < 0) e.plain_col[v] = e.col[v];
}

// Vertex expressions of the others: a member of a class with a column is that column; a
// dependent is built from its masters (never dependents themselves).
void VertexExpressions(int n, const std::vector<char>& dependent, Elimination& e) {
  e.e_ptr.assign(n + 1, 0);
  std::vector<int> dep_of;
  if (!e.dep_vertex.empty()) {
    dep_of.assign(n, -1);
    for (size_t k = 0; k < e.dep_vertex.size(); ++k) dep_of[e.dep_vertex[k]] = static_cast<int>(k);
  }
  size_t most = 2 * e.dep_vertex.size();  // terms: two per dependent, one per other vertex
  for (int v = 0; v < n; ++v) most += !dependent[v] && e.plain_col[v] < 0;
  e.e_col.resize(most);
  e.e_coeff.resize(most);
  int terms = 0;  // written to e_col, e_coeff
  for (int v = 0; v < n; ++v) {
    if (dependent[v]) {
      const int k = dep_of[v];
      const LCplx g = e.dep_gamma[k];
      const int at = terms;
      auto add = [&](int master, LCplx c) {
        const int col = e.col[e.root[master]];
        if (col < 0) return;
        for (int q = at; q < terms; ++q)
          if (e.e_col[q] == col) {
            e.e_coeff[q] += c;
            return;
          }
        e.e_col[terms] = col;
        e.e_coeff[terms++] = c;
      };
      add(e.dep_m1[k], 1.0L - g);
      add(e.dep_m2[k], g);
    } else if (e.plain_col[v] < 0 && e.col[e.root[v]] >= 0) {
      e.e_col[terms] = e.col[e.root[v]];
      e.e_coeff[terms++] = 1.0L;
    }
    e.e_ptr[v + 1] = terms;
  }
  e.e_col.resize(terms);
  e.e_coeff.resize(terms);
}

}  // namespace

void BuildElimination(const PathEditState& d, bool step1, Elimination& e) {
  const int n = d.vertices;
  e.vertices = n;
  e.root.assign(n, 0);
  const std::vector<char> dependent = SimilarityDependents(d, step1, e);
  CollectTies(d, step1, e);
  SpanningForest(n, dependent, e);
  NumberColumns(d, n, e);
  VertexExpressions(n, dependent, e);
}

}  // namespace mocapedit::detail
