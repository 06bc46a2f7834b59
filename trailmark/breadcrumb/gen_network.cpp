// SPDX-License-Identifier: MIT
#include "trailmark/breadcrumb/gen_network.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "trailmark/radio/path_loss.h"

namespace trailmark::breadcrumb {

namespace {
constexpr double kLn10 = 2.302585092994046;
}

ScalarModel::Linear ScalarModel::Linearize(double d) const {
  d = std::max(d, min_distance_m);
  if (kind == Kind::kRange) return {d, 1.0};
  const double mu = alpha_dbm - 10.0 * path_loss_exponent * std::log10(d);
  const double slope = -10.0 * path_loss_exponent / (kLn10 * d);
  // Beyond 8 sigma above the truncation the kept packets' mean is the channel's (to 5e-15 dB).
  if (!(mu < truncation_dbm + 8.0 * sigma_db)) return {mu, slope};
  const radio::TruncatedMean m = radio::TruncatedNormalMean(mu, sigma_db, truncation_dbm);
  return {m.mean, slope * m.d_mean_d_mu};
}

double ScalarModel::Predict(double d) const { return Linearize(d).predicted; }

double ScalarModel::Slope(double d) const { return Linearize(d).slope; }

ScalarModel::SecondOrder ScalarModel::SecondOrderTerms(const Vec2& delta_n,
                                                       const Mat2& cov_m2) const {
  const double d = delta_n.norm();
  if (!(d > min_distance_m) || !cov_m2.allFinite()) return {};
  const Vec2 u = delta_n / d, w(-u.y(), u.x());
  const double p_rr = u.dot(cov_m2 * u), p_tt = w.dot(cov_m2 * w), p_rt = u.dot(cov_m2 * w);
  const double slope = Slope(d);
  // h''(d): 0 for a range; for RSSI the slope's own derivative (central difference, which also
  // covers the truncated mean).
  double curvature = 0;
  if (kind == Kind::kRssiDb) {
    const double eps = 1e-4 * d;
    curvature = (Slope(d + eps) - Slope(d - eps)) / (2 * eps);
  }
  const double a = curvature, b = slope / d;  // H2 in the (u, w) basis: diag(a, b)
  SecondOrder s;
  s.mean_shift = 0.5 * (a * p_rr + b * p_tt);
  s.variance = 0.5 * (a * a * p_rr * p_rr + 2 * a * b * p_rt * p_rt + b * b * p_tt * p_tt);
  const double cap = std::abs(slope) * std::sqrt(std::max(p_rr + p_tt, 0.0));
  s.mean_shift = std::clamp(s.mean_shift, -cap, cap);
  return s;
}

GenNetwork::GenNetwork(GenOptions options) : options_(options) {}

NodeIndex GenNetwork::AddNode(const Vec2& initial_estimate, bool regularize) {
  NodeIndex i;
  if (!free_.empty()) {
    i = free_.back();
    free_.pop_back();
  } else {
    i = static_cast<NodeIndex>(nodes_.size());
    nodes_.emplace_back();
    pattern_dirty_ = true;
  }
  Node& n = nodes_[i];
  n = Node{};
  n.active = true;
  n.x_hat = initial_estimate;
  ++active_count_;
  // Factorize() compares the block pattern with the analysed one before re-analysing.
  pattern_dirty_ = true;
  const double w =
      regularize ? 1.0 / (options_.regularization_sigma_m * options_.regularization_sigma_m) : 0.0;
  n.L_ii = Mat2::Identity() * w;  // eq. (13) plus a negligible prior
  n.b = w * initial_estimate;
  dirty_ = true;
  return i;
}

Mat2& GenNetwork::OffBlock(NodeIndex i, NodeIndex j) {
  for (auto& blk : nodes_[i].off) {
    if (blk.j == j) return blk.L;
  }
  nodes_[i].off.push_back({j, Mat2::Zero()});
  nodes_[j].off.push_back({i, Mat2::Zero()});
  pattern_dirty_ = true;
  return nodes_[i].off.back().L;
}

void GenNetwork::AddPrior(NodeIndex i, const Vec2& mean, const Mat2& cov) {
  AddRelativeToAnchor(i, Vec2::Zero(), mean, cov);
}

void GenNetwork::AddRate(NodeIndex i, int c, const Vec2& v) {
  if (c < 0 || c >= considers_)
    throw std::invalid_argument("GenNetwork: unknown consider parameter");
  auto& db = nodes_[i].db;
  if (db.size() <= static_cast<std::size_t>(c)) db.resize(c + 1, Vec2::Zero());
  db[c] += v;
}

Vec2 GenNetwork::Sensitivity(NodeIndex i, int c) {
  if (!IsActive(i) || c < 0) return Vec2::Zero();
  if (sensitivities_stale_ && factor_valid_ && !dirty_) {
    SolveSensitivities();
    sensitivities_stale_ = false;
  }
  const auto& sens = nodes_[i].sens;
  return static_cast<std::size_t>(c) < sens.size() ? sens[c] : Vec2::Zero();
}

void GenNetwork::AddRelative(NodeIndex i, NodeIndex j, const Vec2& zeta, const Mat2& cov,
                             const std::vector<ConsiderRate>& rates) {
  if (!IsActive(i) || !IsActive(j) || i == j) throw std::invalid_argument("AddRelative: bad nodes");
  const Mat2 W = cov.inverse();  // conductance = 1 / resistance, R_k = P_k
  // eq. (11)
  nodes_[i].L_ii += W;
  nodes_[j].L_ii += W;
  OffBlock(i, j) -= W;
  for (auto& blk : nodes_[j].off) {
    if (blk.j == i) blk.L -= W;  // W symmetric: L_ji = L_ij^T
  }
  nodes_[i].b += W * zeta;
  nodes_[j].b -= W * zeta;
  for (const ConsiderRate& r : rates) {
    AddRate(i, r.parameter, W * r.rate);
    AddRate(j, r.parameter, -(W * r.rate));
  }
  dirty_ = true;
}

void GenNetwork::AddLinear(const std::vector<NodeIndex>& nodes, const std::vector<Mat2>& J,
                           const Vec2& z, const Mat2& cov, const std::vector<ConsiderRate>& rates) {
  if (nodes.size() != J.size() || nodes.empty()) throw std::invalid_argument("AddLinear: sizes");
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    if (!IsActive(nodes[a])) throw std::invalid_argument("AddLinear: inactive node");
    for (std::size_t c = a + 1; c < nodes.size(); ++c) {
      if (nodes[a] == nodes[c]) throw std::invalid_argument("AddLinear: repeated node");
    }
  }
  const Mat2 W = cov.inverse();
  for (std::size_t a = 0; a < nodes.size(); ++a) {
    const Mat2 JtW = J[a].transpose() * W;
    nodes_[nodes[a]].L_ii += JtW * J[a];
    nodes_[nodes[a]].b += JtW * z;
    for (const ConsiderRate& r : rates) AddRate(nodes[a], r.parameter, JtW * r.rate);
    for (std::size_t c = a + 1; c < nodes.size(); ++c) {
      const Mat2 block = JtW * J[c];  // L_ac; L_ca = L_ac^T
      OffBlock(nodes[a], nodes[c]) += block;
      for (auto& blk : nodes_[nodes[c]].off) {
        if (blk.j == nodes[a]) blk.L += block.transpose();
      }
    }
  }
  dirty_ = true;
}

void GenNetwork::AddRelativeToAnchor(NodeIndex i, const Vec2& anchor, const Vec2& zeta,
                                     const Mat2& cov) {
  if (!IsActive(i)) throw std::invalid_argument("AddRelativeToAnchor: bad node");
  const Mat2 W = cov.inverse();
  // eq. (12)
  nodes_[i].L_ii += W;
  nodes_[i].b += W * (zeta + anchor);
  dirty_ = true;
}

void GenNetwork::AddLinearizedScalar(NodeIndex i, NodeIndex j, const Vec2& anchor, double z,
                                     double variance, const ScalarModel& model, const Vec2& offset,
                                     NodeIndex bias, const std::vector<ConsiderRate>& rates) {
  const Vec2 xi = nodes_[i].x_hat;
  const Vec2 xj = j >= 0 ? nodes_[j].x_hat : anchor;
  const Vec2 diff = xi + offset - xj;
  const double d = diff.norm();
  const Vec2 u = d > 1e-9 ? Vec2(diff / d) : Vec2(1.0, 0.0);
  // h_ij = (x_i - x_j)^T / (|x_i - x_j| + eps_ij), breadcrumb paper after eq. (19)
  const Vec2 bias_hat = bias >= 0 ? nodes_[bias].x_hat : Vec2::Zero();
  const double gain = 1.0 + bias_hat.y();
  const ScalarModel::Linear lin = model.Linearize(d);
  const Vec2 h = gain * lin.slope * u;  // dh/dx_i; dh/dx_j = -h
  NodeIndex nodes[3];
  Vec2 rows[3];
  int n = 0;
  nodes[n] = i, rows[n++] = h;
  if (j >= 0) nodes[n] = j, rows[n++] = -h;
  if (bias >= 0) nodes[n] = bias, rows[n++] = Vec2(1.0, lin.predicted);  // d/d(offset, scale)
  // eq. (19): b += H^T P^-1 (z - h(x_hat) + H x_hat); eq. (18): L += H^T P^-1 H
  const double predicted = gain * lin.predicted + bias_hat.x();
  double hx = 0;
  for (int k = 0; k < n; ++k) hx += rows[k].dot(nodes_[nodes[k]].x_hat);
  const double w = 1.0 / variance;
  const double r = z - predicted + hx;
  for (int a = 0; a < n; ++a) {
    nodes_[nodes[a]].L_ii += w * rows[a] * rows[a].transpose();
    nodes_[nodes[a]].b += w * rows[a] * r;
    // r moves with the offset by -h^T d offset (the prediction's slope along it).
    for (const ConsiderRate& cr : rates)
      AddRate(nodes[a], cr.parameter, -w * h.dot(cr.rate) * rows[a]);
    for (int c = a + 1; c < n; ++c) {
      const Mat2 block = w * rows[a] * rows[c].transpose();  // L_ac
      OffBlock(nodes[a], nodes[c]) += block;
      for (auto& blk : nodes_[nodes[c]].off) {
        if (blk.j == nodes[a]) blk.L += block.transpose();
      }
    }
  }
  dirty_ = true;
}

void GenNetwork::AddScalar(NodeIndex i, NodeIndex j, double z, double variance,
                           const ScalarModel& model, const Vec2& offset, NodeIndex bias,
                           const std::vector<ConsiderRate>& rates) {
  if (!IsActive(i) || !IsActive(j) || i == j || !(variance > 0) ||
      (bias >= 0 && (!IsActive(bias) || bias == i || bias == j))) {
    throw std::invalid_argument("AddScalar: bad nodes or variance");
  }
  AddLinearizedScalar(i, j, Vec2::Zero(), z, variance, model, offset, bias, rates);
}

void GenNetwork::AddScalarToAnchor(NodeIndex i, const Vec2& anchor, double z, double variance,
                                   const ScalarModel& model, const Vec2& offset) {
  if (!IsActive(i) || !(variance > 0)) throw std::invalid_argument("AddScalarToAnchor: bad input");
  AddLinearizedScalar(i, -1, anchor, z, variance, model, offset);
}

int GenNetwork::AddPersistent(NodeIndex i, NodeIndex j, const ScalarModel& model) {
  if (!IsActive(i) || !IsActive(j) || i == j) throw std::invalid_argument("AddPersistent: bad nodes");
  const int id = static_cast<int>(persistent_.size());
  Persistent e;
  e.i = i;
  e.j = j;
  e.model = model;
  e.active = true;
  persistent_.push_back(e);
  nodes_[i].persistent.push_back(id);
  nodes_[j].persistent.push_back(id);
  OffBlock(i, j);  // reserve the pattern
  ++active_persistent_;
  return id;
}

int GenNetwork::AddScalarPersistent(NodeIndex i, NodeIndex j, double z, double variance,
                                    const ScalarModel& model, const Vec2& offset, NodeIndex bias,
                                    const std::vector<ConsiderRate>& rates) {
  if (!IsActive(i) || !IsActive(j) || i == j || !(variance > 0) || !std::isfinite(z) ||
      (bias >= 0 && (!IsActive(bias) || bias == i || bias == j))) {
    throw std::invalid_argument("AddScalarPersistent: bad nodes or variance");
  }
  for (const ConsiderRate& cr : rates) {
    if (cr.parameter < 0 || cr.parameter >= considers_)
      throw std::invalid_argument("GenNetwork: unknown consider parameter");
  }
  const int id = AddPersistent(i, j, model);
  Persistent& e = persistent_[id];
  e.offset = offset;
  e.rates = rates;
  e.information = 1.0 / variance;
  e.weighted_z = z / variance;
  if (bias >= 0) {
    e.bias = bias;
    nodes_[bias].persistent.push_back(id);
    OffBlock(i, bias);
    OffBlock(j, bias);
  }
  dirty_ = true;
  return id;
}

void GenNetwork::AccumulatePersistent(int edge, double z, double variance) {
  Persistent& e = persistent_.at(edge);
  if (!e.active || !(variance > 0)) throw std::invalid_argument("AccumulatePersistent: bad edge");
  e.information += 1.0 / variance;
  e.weighted_z += z / variance;
  dirty_ = true;
}

void GenNetwork::SetPersistentFloor(int edge, double floor_variance) {
  persistent_.at(edge).floor_variance = std::max(0.0, floor_variance);
  dirty_ = true;
}

void GenNetwork::SetPersistentModel(int edge, const ScalarModel& model) {
  persistent_.at(edge).model = model;
  dirty_ = true;
}

void GenNetwork::SetPersistentWeight(int edge, double w) {
  persistent_.at(edge).weight = std::clamp(w, 1e-6, 1.0);
  dirty_ = true;
}

double GenNetwork::PersistentResidual(int edge) const {
  const Persistent& e = persistent_.at(edge);
  if (!e.active || e.information <= 0) return 0;
  const double d = (nodes_[e.i].x_hat + e.offset - nodes_[e.j].x_hat).norm();
  const Vec2 bias_hat = e.bias >= 0 ? nodes_[e.bias].x_hat : Vec2::Zero();
  const double predicted = (1.0 + bias_hat.y()) * e.model.Predict(d) + bias_hat.x();
  return (e.Mean() - predicted) / std::sqrt(e.Variance());
}

void GenNetwork::AddSecondOrderTerms(int edge, const Mat2& cov_m2) {
  Persistent& e = persistent_.at(edge);
  if (!e.active || e.information <= 0) return;
  const Vec2 diff = nodes_[e.i].x_hat + e.offset - nodes_[e.j].x_hat;
  const ScalarModel::SecondOrder so = e.model.SecondOrderTerms(diff, cov_m2);
  const double f = 1.0 + (e.bias >= 0 ? nodes_[e.bias].x_hat.y() : 0.0);
  e.weighted_z -= f * so.mean_shift * e.information;
  e.floor_variance += f * f * so.variance;
  dirty_ = true;
}

void GenNetwork::FoldPersistent(int edge) {
  Persistent& e = persistent_[edge];
  if (!e.active) return;
  e.active = false;
  --active_persistent_;
  if (e.information > 0) {
    AddLinearizedScalar(e.i, e.j, Vec2::Zero(), e.Mean(), e.Variance(), e.model, e.offset, e.bias,
                        e.rates);
  }
  for (NodeIndex n : {e.i, e.j, e.bias}) {
    if (n < 0) continue;
    auto& list = nodes_[n].persistent;
    list.erase(std::remove(list.begin(), list.end(), edge), list.end());
  }
  e.rates.clear();
  e.rates.shrink_to_fit();
}

GenNetwork::Linearized GenNetwork::LinearizePersistent(const Persistent& e) const {
  const Vec2 xi = nodes_[e.i].x_hat, xj = nodes_[e.j].x_hat;
  const Vec2 diff = xi + e.offset - xj;
  const double d = diff.norm();
  const Vec2 u = d > 1e-9 ? Vec2(diff / d) : Vec2(1.0, 0.0);
  const ScalarModel::Linear lin = e.model.Linearize(d);
  Linearized out;
  out.nodes = {e.i, e.j, e.bias};
  out.w = 1.0 / e.Variance();
  if (e.bias < 0) {
    const Vec2 h = lin.slope * u;
    out.rows = {h, Vec2(-h), Vec2::Zero()};
    out.r = e.Mean() - lin.predicted + h.dot(diff) - h.dot(e.offset);  // eq. (19)
    return out;
  }
  // z = (1 + scale) h(d) + offset: as AddLinearizedScalar
  const Vec2 bias_hat = nodes_[e.bias].x_hat;
  const double gain = 1.0 + bias_hat.y();
  const Vec2 h = gain * lin.slope * u;
  out.rows = {h, Vec2(-h), Vec2(1.0, lin.predicted)};
  out.n = 3;
  out.r = e.Mean() - (gain * lin.predicted + bias_hat.x()) + h.dot(diff) - h.dot(e.offset) +
          out.rows[2].dot(bias_hat);
  return out;
}

void GenNetwork::DeleteNode(NodeIndex k) { Marginalize<1>({k}); }

void GenNetwork::DeleteNodes(NodeIndex a, NodeIndex b) {
  if (a == b) throw std::invalid_argument("DeleteNodes: the same node twice");
  Marginalize<2>({a, b});
}

template <int K>
void GenNetwork::Marginalize(const std::array<NodeIndex, K>& ks) {
  constexpr int D = 2 * K;
  using MatKK = Eigen::Matrix<double, D, D>;
  using MatMK = Eigen::Matrix<double, 2, D>;
  for (NodeIndex k : ks) {
    if (!IsActive(k)) throw std::invalid_argument("DeleteNode: inactive node");
  }
  for (NodeIndex k : ks) {
    while (!nodes_[k].persistent.empty()) FoldPersistent(nodes_[k].persistent.back());
  }
  // eq. (17) for the set K at once: L = L_pp - L_pK L_KK^-1 L_Kp,  b = b_p - L_pK L_KK^-1 b_K
  MatKK L_KK = MatKK::Zero();
  Eigen::Matrix<double, D, 1> b_K;
  if (mark_.size() < nodes_.size()) mark_.assign(nodes_.size(), -1);
  // Per-instantiation scratch (no allocation per marginalization once warm).
  thread_local std::vector<MatMK, Eigen::aligned_allocator<MatMK>> scratch_lmk, scratch_gain;
  scratch_neighbours_.clear();
  scratch_lmk.clear();
  for (int a = 0; a < K; ++a) {
    const Node& na = nodes_[ks[a]];
    L_KK.template block<2, 2>(2 * a, 2 * a) = na.L_ii;
    b_K.template segment<2>(2 * a) = na.b;
    for (const auto& blk : na.off) {
      int in_k = -1;
      for (int c = 0; c < K; ++c) in_k = blk.j == ks[c] ? c : in_k;
      if (in_k >= 0) {
        L_KK.template block<2, 2>(2 * a, 2 * in_k) = blk.L;  // L_{k_a k_c}
        continue;
      }
      int pos = mark_[blk.j];
      if (pos < 0) {
        pos = static_cast<int>(scratch_neighbours_.size());
        mark_[blk.j] = pos;
        scratch_neighbours_.push_back(blk.j);
        scratch_lmk.push_back(MatMK::Zero());
      }
      scratch_lmk[pos].template block<2, 2>(0, 2 * a) = blk.L.transpose();  // L_{m k_a}
    }
  }
  for (NodeIndex m : scratch_neighbours_) mark_[m] = -1;
  const MatKK L_KK_inv = L_KK.inverse();
  const std::size_t N = scratch_neighbours_.size();
  scratch_gain.resize(N);
  scratch_fill_.resize(N * N);
  // The consider parameters' d b / d theta, alike (b_K's derivative).
  std::size_t rated = 0;
  for (NodeIndex k : ks) rated = std::max(rated, nodes_[k].db.size());
  thread_local std::vector<Eigen::Matrix<double, D, 1>> scratch_db_K;
  scratch_db_K.assign(rated, Eigen::Matrix<double, D, 1>::Zero());
  for (int a = 0; a < K; ++a) {
    const auto& db = nodes_[ks[a]].db;
    for (std::size_t c = 0; c < db.size(); ++c) scratch_db_K[c].template segment<2>(2 * a) = db[c];
  }
  for (std::size_t a = 0; a < N; ++a) {
    const MatMK G = scratch_lmk[a] * L_KK_inv;  // L_mK L_KK^-1
    scratch_gain[a] = G;
    Node& m = nodes_[scratch_neighbours_[a]];
    m.b -= G * b_K;
    for (std::size_t c = 0; c < rated; ++c) {
      if (!scratch_db_K[c].isZero(0.0))
        AddRate(scratch_neighbours_[a], static_cast<int>(c), -(G * scratch_db_K[c]));
    }
    m.L_ii -= G * scratch_lmk[a].transpose();
    m.L_ii = 0.5 * (m.L_ii + m.L_ii.transpose());
  }
  for (std::size_t a = 0; a < N; ++a) {
    for (std::size_t c = a + 1; c < N; ++c) {
      scratch_fill_[a * N + c] = scratch_gain[a] * scratch_lmk[c].transpose();  // (m, n)
    }
  }
  for (std::size_t a = 0; a < N; ++a) {
    auto& list = nodes_[scratch_neighbours_[a]].off;
    for (std::size_t p = 0; p < list.size();) {  // drop the blocks to K
      bool to_k = false;
      for (NodeIndex k : ks) to_k = to_k || list[p].j == k;
      if (to_k) {
        list[p] = list.back();
        list.pop_back();
      } else {
        mark_[list[p].j] = static_cast<int>(p);
        ++p;
      }
    }
    for (std::size_t c = 0; c < N; ++c) {
      if (c == a) continue;
      // (m, n) and (n, m) = (m, n)^T from the same product: L stays exactly symmetric.
      const Mat2 fill = a < c ? scratch_fill_[a * N + c] : Mat2(scratch_fill_[c * N + a].transpose());
      const NodeIndex n = scratch_neighbours_[c];
      const int p = mark_[n];
      if (p < 0) {
        list.push_back({n, -fill});
        mark_[n] = static_cast<int>(list.size()) - 1;
        pattern_dirty_ = true;
      } else {
        list[p].L -= fill;
      }
    }
    for (const auto& blk : list) mark_[blk.j] = -1;
  }
  for (NodeIndex k : ks) {
    const int compact = nodes_[k].compact;  // the slot keeps its number for a MoveNode into it
    nodes_[k] = Node{};
    nodes_[k].compact = compact;
    free_.push_back(k);
    --active_count_;
  }
  pattern_dirty_ = true;
  dirty_ = true;
}

NodeIndex GenNetwork::MoveNode(NodeIndex from, NodeIndex to) {
  if (!IsActive(from) || to < 0 || to >= static_cast<NodeIndex>(nodes_.size()) ||
      nodes_[to].active) {
    throw std::invalid_argument("MoveNode: needs an active node and a free slot");
  }
  free_.erase(std::remove(free_.begin(), free_.end(), to), free_.end());
  const int compact = nodes_[to].compact;
  nodes_[to] = std::move(nodes_[from]);
  nodes_[to].compact = compact;
  for (auto& blk : nodes_[to].off) {
    for (auto& back : nodes_[blk.j].off) {
      if (back.j == from) {  // one block per pair
        back.j = to;
        break;
      }
    }
  }
  for (int e : nodes_[to].persistent) {
    if (persistent_[e].i == from) persistent_[e].i = to;
    if (persistent_[e].j == from) persistent_[e].j = to;
    if (persistent_[e].bias == from) persistent_[e].bias = to;
  }
  nodes_[from] = Node{};
  free_.push_back(from);
  pattern_dirty_ = true;
  dirty_ = true;
  return to;
}

std::size_t GenNetwork::off_diagonal_blocks() const {
  std::size_t n = 0;
  for (const auto& node : nodes_) n += node.off.size();
  return n / 2;
}

void GenNetwork::CompactIndices() {
  // Keep the current numbering (the fill-reducing one of the last analysis) while the set of
  // active slots is the same; renumber in slot order otherwise.
  bool same_set = order_.size() == static_cast<std::size_t>(active_count_);
  for (std::size_t k = 0; same_set && k < order_.size(); ++k) {
    same_set = nodes_[order_[k]].active && nodes_[order_[k]].compact == static_cast<int>(k);
  }
  active_set_same_ = same_set;
  if (same_set) return;
  order_.clear();
  for (NodeIndex i = 0; i < static_cast<NodeIndex>(nodes_.size()); ++i) {
    nodes_[i].compact = -1;
    if (nodes_[i].active) {
      nodes_[i].compact = static_cast<int>(order_.size());
      order_.push_back(i);
    }
  }
}

std::vector<std::pair<int, int>> GenNetwork::BlockPattern() const {
  std::vector<std::pair<int, int>> pattern;
  pattern.reserve(analysed_pattern_.size() + 16);
  std::vector<std::size_t> row_start(order_.size());
  for (std::size_t r = 0; r < order_.size(); ++r) {
    const std::size_t start = pattern.size();
    for (const auto& blk : nodes_[order_[r]].off) {
      const int c = nodes_[blk.j].compact;
      if (c < static_cast<int>(r)) pattern.emplace_back(static_cast<int>(r), c);
    }
    std::sort(pattern.begin() + static_cast<std::ptrdiff_t>(start), pattern.end());
    pattern.emplace_back(static_cast<int>(r), static_cast<int>(r));
  }
  return pattern;
}

void GenNetwork::FillReducingOrder() {
  // Approximate minimum degree on the graph of 2x2 blocks (4x smaller than the scalar one);
  // the numbering becomes the compact indices, so the factorization needs no permutation.
  const int nb = static_cast<int>(order_.size());
  std::vector<Eigen::Triplet<int>> t;
  for (const auto& [r, c] : BlockPattern()) t.emplace_back(r, c, 1);
  Eigen::SparseMatrix<int> B(nb, nb);
  B.setFromTriplets(t.begin(), t.end());
  Eigen::PermutationMatrix<Eigen::Dynamic, Eigen::Dynamic, int> pinv;
  Eigen::AMDOrdering<int>()(B, pinv);  // pinv: new position -> old position
  std::vector<NodeIndex> ordered(order_.size());
  for (int k = 0; k < nb; ++k) ordered[k] = order_[pinv.indices()(k)];
  order_ = std::move(ordered);
  for (int k = 0; k < nb; ++k) nodes_[order_[k]].compact = k;
}

void GenNetwork::PreparePattern() {
  // The block pattern (lower triangle, compact indices, row by row): the symbolic analysis
  // (elimination tree) and the matrix structure are reused while it holds; when it changes, a
  // new fill-reducing numbering is computed. Runs before any right-hand side is built, as it
  // may renumber. (Persistent edges add entries inside blocks that are already in the pattern.)
  if (!pattern_dirty_) {
    pattern_same_ = true;
    return;
  }
  if (prefer_dense_ && active_set_same_) {
    // The dense factor needs only the numbering, which holds while the same nodes are active
    // (a mobile node's new state moved into its old slot): no pattern to compare. The sparse
    // structures are rebuilt at the next analysis (when the set changes), which re-decides.
    pattern_same_ = true;
    pattern_dirty_ = false;
    return;
  }
  pattern_same_ = analyses_ > 0 && BlockPattern() == analysed_pattern_;
  if (!pattern_same_) {
    FillReducingOrder();
    analysed_pattern_ = BlockPattern();
  }
  pattern_dirty_ = false;
}

bool GenNetwork::FactorizeDense(int n, const std::vector<Eigen::Triplet<double>>& extra_L) {
  // The lower triangle of L in the compact numbering, then a blocked dense Cholesky (LLT reads
  // the lower triangle only).
  dense_A_.resize(n, n);
  dense_A_.triangularView<Eigen::Lower>().setZero();
  for (NodeIndex slot : order_) {
    const Node& node = nodes_[slot];
    const int r = node.compact * 2;
    dense_A_(r, r) = node.L_ii(0, 0);
    dense_A_(r + 1, r) = node.L_ii(1, 0);
    dense_A_(r + 1, r + 1) = node.L_ii(1, 1);
    for (const auto& blk : node.off) {
      const int c = nodes_[blk.j].compact * 2;
      if (c < r) dense_A_.block<2, 2>(r, c) = blk.L;
    }
  }
  for (const auto& t : extra_L) dense_A_(t.row(), t.col()) += t.value();
  dense_llt_.compute(dense_A_);
  dense_ = true;
  ++factorizations_;
  ++dense_factorizations_;
  max_dimension_ = std::max(max_dimension_, n);
  factor_valid_ =
      dense_llt_.info() == Eigen::Success && (dense_llt_.matrixLLT().diagonal().array() > 0).all();
  return factor_valid_;
}

bool GenNetwork::Factorize(const std::vector<Eigen::Triplet<double>>& extra_L) {
  const int n = static_cast<int>(order_.size()) * 2;
  const bool same_pattern = pattern_same_ && matrix_.rows() == n && analyses_ > 0;
  if (same_pattern && prefer_dense_) return FactorizeDense(n, extra_L);
  if (same_pattern) {
    // Values only, in place, column by column (no triplets, no sort, no search): block (r, c)
    // of the lower triangle is the transpose of block (c, r) kept in column node c's list.
    double* val = matrix_.valuePtr();
    const int* inner = matrix_.innerIndexPtr();
    const int* outer = matrix_.outerIndexPtr();
    if (row_pos_.size() < static_cast<std::size_t>(n)) row_pos_.assign(n, -1);
    for (NodeIndex slot : order_) {
      const Node& node = nodes_[slot];
      const int c = node.compact * 2;
      for (int cc = 0; cc < 2; ++cc) {
        const int col = c + cc;
        for (int p = outer[col]; p < outer[col + 1]; ++p) {
          row_pos_[inner[p]] = p;
          val[p] = 0.0;
        }
        if (cc == 0) {
          val[row_pos_[c]] = node.L_ii(0, 0);
          val[row_pos_[c + 1]] = node.L_ii(1, 0);
        } else {
          val[row_pos_[c + 1]] = node.L_ii(1, 1);
        }
        for (const auto& blk : node.off) {
          const int r = nodes_[blk.j].compact * 2;
          if (r < c) continue;
          val[row_pos_[r]] = blk.L(cc, 0);      // (r, col) = L_cr(cc, 0)
          val[row_pos_[r + 1]] = blk.L(cc, 1);  // (r + 1, col) = L_cr(cc, 1)
        }
      }
    }
    for (const auto& t : extra_L) matrix_.coeffRef(t.row(), t.col()) += t.value();
  } else {
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(order_.size() * 3 + off_diagonal_blocks() * 4 + extra_L.size());
    for (NodeIndex slot : order_) {
      const Node& node = nodes_[slot];
      const int r = node.compact * 2;
      triplets.emplace_back(r, r, node.L_ii(0, 0));
      triplets.emplace_back(r + 1, r, node.L_ii(1, 0));
      triplets.emplace_back(r + 1, r + 1, node.L_ii(1, 1));
      for (const auto& blk : node.off) {
        const int c = nodes_[blk.j].compact * 2;
        if (c > r) continue;  // lower triangle only (SimplicialLDLT reads the lower part)
        for (int a = 0; a < 2; ++a) {
          for (int bb = 0; bb < 2; ++bb) triplets.emplace_back(r + a, c + bb, blk.L(a, bb));
        }
      }
    }
    triplets.insert(triplets.end(), extra_L.begin(), extra_L.end());
    matrix_.resize(n, n);
    matrix_.setFromTriplets(triplets.begin(), triplets.end());
    solver_.analyzePattern(matrix_);
    ++analyses_;
    etree_valid_ = false;
  }
  solver_.factorize(matrix_);
  dense_ = false;
  ++factorizations_;
  max_dimension_ = std::max(max_dimension_, n);
  const auto factor_nonzeros =
      static_cast<std::size_t>(solver_.matrixL().nestedExpression().nonZeros());
  max_factor_nonzeros_ = std::max(max_factor_nonzeros_, factor_nonzeros);
  if (!same_pattern) {  // the strictly lower triangle holds n (n - 1) / 2 entries
    prefer_dense_ = static_cast<double>(factor_nonzeros) >
                    options_.dense_fill_share * 0.5 * static_cast<double>(n) * (n - 1);
  }
  factor_valid_ = solver_.info() == Eigen::Success && (solver_.vectorD().array() > 0).all();
  return factor_valid_;
}

bool GenNetwork::Solve() {
  if (!dirty_) return factor_valid_;
  if (order_.size() != static_cast<std::size_t>(active_count_) || pattern_dirty_) CompactIndices();
  PreparePattern();
  if (order_.empty()) {
    dirty_ = false;
    return true;
  }
  const int n = static_cast<int>(order_.size()) * 2;
  bool have_persistent = false;
  for (NodeIndex slot : order_) have_persistent = have_persistent || !nodes_[slot].persistent.empty();
  const int iterations = have_persistent ? std::max(1, options_.max_relinearization_iterations) : 1;
  for (int it = 0; it < iterations; ++it) {
    std::vector<Eigen::Triplet<double>> extra;
    Eigen::VectorXd rhs(n);
    for (NodeIndex slot : order_) rhs.segment<2>(nodes_[slot].compact * 2) = nodes_[slot].b;
    if (have_persistent) {
      for (const auto& e : persistent_) {
        if (!e.active || e.information <= 0) continue;
        const Linearized lin = LinearizePersistent(e);
        int c[3];
        for (int a = 0; a < lin.n; ++a) c[a] = nodes_[lin.nodes[a]].compact * 2;
        auto add = [&](int r0, int c0, const Mat2& m) {
          for (int a = 0; a < 2; ++a) {
            for (int bb = 0; bb < 2; ++bb) {
              if (r0 + a >= c0 + bb) extra.emplace_back(r0 + a, c0 + bb, m(a, bb));
            }
          }
        };
        // eq. (18): w row_a row_c^T, the lower triangle only (diagonal blocks first)
        for (int a = 0; a < lin.n; ++a)
          add(c[a], c[a], lin.w * lin.rows[a] * lin.rows[a].transpose());
        for (int a = 0; a < lin.n; ++a) {
          for (int k = a + 1; k < lin.n; ++k) {
            if (c[a] > c[k])
              add(c[a], c[k], lin.w * lin.rows[a] * lin.rows[k].transpose());
            else
              add(c[k], c[a], lin.w * lin.rows[k] * lin.rows[a].transpose());
          }
        }
        for (int a = 0; a < lin.n; ++a) rhs.segment<2>(c[a]) += lin.w * lin.rows[a] * lin.r;
      }
    }
    if (!Factorize(extra)) return false;
    const Eigen::VectorXd x = dense_ ? Eigen::VectorXd(dense_llt_.solve(rhs)) : solver_.solve(rhs);
    if (!x.allFinite()) {
      factor_valid_ = false;
      return false;
    }
    double change = 0;
    for (NodeIndex slot : order_) {
      const Vec2 nx = x.segment<2>(nodes_[slot].compact * 2);
      change = std::max(change, (nx - nodes_[slot].x_hat).norm());
      nodes_[slot].x_hat = nx;
    }
    if (change < options_.relinearization_tolerance_m) break;
  }
  sensitivities_stale_ = true;
  dirty_ = false;
  return true;
}

void GenNetwork::SolveSensitivities() {
  std::size_t rated = 0;
  for (NodeIndex slot : order_) rated = std::max(rated, nodes_[slot].db.size());
  for (const auto& e : persistent_) {
    if (!e.active) continue;
    for (const ConsiderRate& cr : e.rates)
      rated = std::max(rated, static_cast<std::size_t>(cr.parameter) + 1);
  }
  if (rated == 0) {
    for (NodeIndex slot : order_) nodes_[slot].sens.clear();
    return;
  }
  const int n = static_cast<int>(order_.size()) * 2;
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(n, static_cast<Eigen::Index>(rated));
  for (NodeIndex slot : order_) {
    const auto& db = nodes_[slot].db;
    for (std::size_t c = 0; c < db.size(); ++c) B.block<2, 1>(nodes_[slot].compact * 2, c) = db[c];
  }
  for (const auto& e : persistent_) {
    // A persistent edge's offset moves with its rates: as AddLinearizedScalar's, at the
    // current linearization (r moves by -row_i^T d offset).
    if (!e.active || e.rates.empty() || e.information <= 0) continue;
    const Linearized lin = LinearizePersistent(e);
    for (const ConsiderRate& cr : e.rates) {
      const double dr = -lin.w * lin.rows[0].dot(cr.rate);
      for (int a = 0; a < lin.n; ++a)
        B.block<2, 1>(nodes_[lin.nodes[a]].compact * 2, cr.parameter) += dr * lin.rows[a];
    }
  }
  const Eigen::MatrixXd X = dense_ ? Eigen::MatrixXd(dense_llt_.solve(B)) : solver_.solve(B);
  ++sensitivity_solves_;
  for (NodeIndex slot : order_) {
    auto& sens = nodes_[slot].sens;
    sens.resize(rated);
    for (std::size_t c = 0; c < rated; ++c) sens[c] = X.block<2, 1>(nodes_[slot].compact * 2, c);
  }
}

Eigen::MatrixXd GenNetwork::MarginalOfRows(const std::vector<int>& rows) {
  if (dense_) {
    // A = L L^T  =>  (A^-1)_ab = y_a^T y_b with y = L^-1 e, zero above the smallest row: one
    // triangular solve on the trailing block (the fill-reducing numbering puts the agents, the
    // nodes of most links, last, so the block is small).
    const int n = static_cast<int>(dense_A_.rows());
    const int K = static_cast<int>(rows.size());
    const int start = *std::min_element(rows.begin(), rows.end());
    const int m = n - start;
    Eigen::MatrixXd Y = Eigen::MatrixXd::Zero(m, K);
    for (int k = 0; k < K; ++k) Y(rows[k] - start, k) = 1.0;
    dense_llt_.matrixLLT().bottomRightCorner(m, m).triangularView<Eigen::Lower>().solveInPlace(Y);
    return Y.transpose() * Y;
  }
  // A = P^T L D L^T P  =>  A^-1 = P^T L^-T D^-1 L^-1 P, so for unit vectors e_a, e_b:
  // (A^-1)_ab = y_a^T D^-1 y_b with y = L^-1 P e. L^-1 of a unit vector is non-zero only on the
  // path from its position to the root of the elimination tree: a forward solve along the union
  // of those paths, not a full solve (the rows of column j of L are ancestors of j).
  const auto& Lm = solver_.matrixL().nestedExpression();
  const Eigen::VectorXd& D = solver_.vectorD();
  const int n = static_cast<int>(Lm.rows());
  const int K = static_cast<int>(rows.size());
  if (!Lm.isCompressed()) {  // never with Eigen's simplicial factor; kept for safety
    Eigen::MatrixXd E = Eigen::MatrixXd::Zero(n, K);
    for (int k = 0; k < K; ++k) E(rows[k], k) = 1.0;
    const Eigen::MatrixXd X = solver_.solve(E);
    Eigen::MatrixXd S(K, K);
    for (int a = 0; a < K; ++a) {
      for (int b = 0; b < K; ++b) S(a, b) = X(rows[a], b);
    }
    return S;
  }
  const int* outer = Lm.outerIndexPtr();
  const int* inner = Lm.innerIndexPtr();
  const double* value = Lm.valuePtr();
  if (!etree_valid_) {
    etree_parent_.assign(n, -1);
    for (int col = 0; col < n; ++col) {
      for (int p = outer[col]; p < outer[col + 1]; ++p) {
        if (inner[p] > col) {
          etree_parent_[col] = inner[p];
          break;
        }
      }
    }
    etree_valid_ = true;
  }
  if (work_.rows() < n || work_.cols() < K) work_ = Eigen::MatrixXd::Zero(n, std::max(K, 4));
  if (visited_.size() < static_cast<std::size_t>(n)) visited_.assign(n, 0);
  path_.clear();
  const auto& perm = solver_.permutationP().indices();  // empty: natural ordering
  for (int k = 0; k < K; ++k) {
    const int start = perm.size() > 0 ? perm(rows[k]) : rows[k];
    work_(start, k) = 1.0;
    for (int v = start; v >= 0 && !visited_[v]; v = etree_parent_[v]) {
      visited_[v] = 1;
      path_.push_back(v);
    }
  }
  std::sort(path_.begin(), path_.end());
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(K, K);
  for (int col : path_) {
    for (int p = outer[col]; p < outer[col + 1]; ++p) {
      const int r = inner[p];
      if (r <= col) continue;
      for (int k = 0; k < K; ++k) work_(r, k) -= value[p] * work_(col, k);
    }
    for (int a = 0; a < K; ++a) {
      for (int b = 0; b < K; ++b) S(a, b) += work_(col, a) * work_(col, b) / D(col);
    }
  }
  for (int col : path_) {
    visited_[col] = 0;
    for (int k = 0; k < K; ++k) work_(col, k) = 0.0;
  }
  return S;
}

Mat2 GenNetwork::Covariance(NodeIndex i) {
  if (!IsActive(i)) throw std::invalid_argument("Covariance: inactive node");
  if (dirty_) Solve();
  if (!factor_valid_) return Mat2::Identity() * 1e12;
  const int c = nodes_[i].compact * 2;
  const Eigen::MatrixXd S = MarginalOfRows({c, c + 1});
  const Mat2 M = S;
  return 0.5 * (M + M.transpose());
}

Eigen::Matrix4d GenNetwork::JointCovariance(NodeIndex i, NodeIndex j) {
  if (!IsActive(i) || !IsActive(j)) throw std::invalid_argument("JointCovariance: inactive node");
  if (dirty_) Solve();
  if (!factor_valid_) return Eigen::Matrix4d::Identity() * 1e12;
  const int ci = nodes_[i].compact * 2, cj = nodes_[j].compact * 2;
  const Eigen::Matrix4d S = MarginalOfRows({ci, ci + 1, cj, cj + 1});
  return 0.5 * (S + S.transpose());
}

void GenNetwork::DenseSystem(Eigen::MatrixXd* L, Eigen::VectorXd* b,
                             std::vector<NodeIndex>* order) const {
  std::vector<NodeIndex> ord;
  std::vector<int> pos(nodes_.size(), -1);
  for (NodeIndex i = 0; i < static_cast<NodeIndex>(nodes_.size()); ++i) {
    if (nodes_[i].active) {
      pos[i] = static_cast<int>(ord.size());
      ord.push_back(i);
    }
  }
  const int n = static_cast<int>(ord.size()) * 2;
  L->setZero(n, n);
  b->setZero(n);
  for (NodeIndex i : ord) {
    L->block<2, 2>(pos[i] * 2, pos[i] * 2) = nodes_[i].L_ii;
    b->segment<2>(pos[i] * 2) = nodes_[i].b;
    for (const auto& blk : nodes_[i].off) L->block<2, 2>(pos[i] * 2, pos[blk.j] * 2) = blk.L;
  }
  for (const auto& e : persistent_) {
    if (!e.active || e.information <= 0) continue;
    const Linearized lin = LinearizePersistent(e);
    for (int a = 0; a < lin.n; ++a) {  // eq. (18)-(19)
      const int ca = pos[lin.nodes[a]] * 2;
      for (int k = 0; k < lin.n; ++k) {
        L->block<2, 2>(ca, pos[lin.nodes[k]] * 2) += lin.w * lin.rows[a] * lin.rows[k].transpose();
      }
      b->segment<2>(ca) += lin.w * lin.rows[a] * lin.r;
    }
  }
  if (order) *order = ord;
}

}  // namespace trailmark::breadcrumb
