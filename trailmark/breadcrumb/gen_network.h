// SPDX-License-Identifier: MIT
#pragma once
/// The generalized electrical network (GEN) of the breadcrumb paper, section IV: the
/// information form of a relative-measurement graph, kept incrementally.
///
///   L x = b                                   eq. (4)-(5):  Sigma = L^-1, x_hat = L^-1 b
///   L = Kirchhoff matrix (block Laplacian)    eq. (7)-(9)   resistances R_k = P_k
///   b = injected "currents"                   eq. (10)
///
/// Operations (section IV-C, IV-D): AddMeasurement (11), with an anchor (12), AddNode (13),
/// DeleteNode by marginalization (14)-(17), AddMeasurement+ for non-linear scalar measurements
/// (18)-(19). Mobile nodes (IV-E) are a chain AddNode -> AddMeasurement -> DeleteNode done by the
/// caller (breadcrumb/localizer.h).
///
/// Beyond the paper (issue 8):
///  - sparse 2x2-block storage; solving by sparse LDL^T (Eigen, AMD ordering) instead of the
///    paper's dense inverse; the symbolic analysis is reused while the sparsity pattern is
///    unchanged (slots of deleted nodes are recycled, so a mobile node replacing its previous
///    state keeps the pattern);
///  - marginal covariances Sigma_ii from two solves with the factor, never a full inverse;
///  - "persistent" scalar edges between nodes that never leave the network (crumb-crumb
///    ranges): kept as factors and re-linearized at every solve (Gauss-Newton), instead of
///    being linearized once. They are folded into L (linearized at the current estimate) only
///    when one of their nodes is deleted.
///
/// State: horizontal position (x, y) per node, metres, navigation frame. The paper writes R^3;
/// floors are separate levels in our missions and z is carried by the PDR, not estimated here.
/// Not thread-safe.

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <array>
#include <cstdint>
#include <limits>
#include <optional>
#include <vector>

#include "trailmark/core/types.h"

namespace trailmark::breadcrumb {

/// Index of a node in the network; slots are recycled after DeleteNode.
using NodeIndex = int;

/// A scalar measurement model of the distance d between two positions: z = h(d) + noise.
struct ScalarModel {
  enum class Kind { kRange, kRssiDb } kind = Kind::kRange;
  double alpha_dbm = -40.0;  ///< kRssiDb: rssi = alpha - 10 n log10(d)
  double path_loss_exponent = 2.3;
  double min_distance_m = 0.3;  ///< linearization guard (eq. (19)'s epsilon_ij in h_ij)
  /// kRssiDb of a receiver that keeps only packets >= truncation_dbm: h is the mean of the kept
  /// ones, the truncated normal's (radio::TruncatedNormalMean with sigma_db, one packet's
  /// shadowing), not alpha - 10 n log10(d) (issue 25). -inf: every packet kept.
  double truncation_dbm = -std::numeric_limits<double>::infinity();
  double sigma_db = 0;

  double Predict(double distance_m) const;
  /// dh/dd at distance_m.
  double Slope(double distance_m) const;
  /// Both at once (one evaluation of the truncated mean).
  struct Linear {
    double predicted;
    double slope;
  };
  Linear Linearize(double distance_m) const;
  /// The second-order terms of h(|delta|) for a difference of positions delta ~ N(delta_n,
  /// cov_m2) (the Gaussian second-order filter: Gelb, Applied Optimal Estimation, 1974, sec.
  /// 6.1; Bar-Shalom, Li, Kirubarajan 2001, sec. 10.3.2). With the Hessian of h in delta,
  /// H2 = h''(d) u u^T + h'(d) / d (I - u u^T), u = delta / d:
  ///   E[h] ~ h(d) + 1/2 tr(H2 P)   (mean_shift),   Var[h] ~ h'^2 u^T P u + 1/2 tr((H2 P)^2)
  /// (variance: the second term only; the first is the linearized one). A range to a node
  /// whose position is uncertain across the line of sight is longer than the distance between
  /// the estimates by about sigma_t^2 / (2 d): committed at the estimate, every such edge pulls
  /// the same way. The shift is kept within the first-order spread |h'| sqrt(tr P), beyond
  /// which the expansion does not hold. Zero at or below min_distance_m.
  struct SecondOrder {
    double mean_shift = 0;
    double variance = 0;
  };
  SecondOrder SecondOrderTerms(const Vec2& delta_n, const Mat2& cov_m2) const;
};

struct GenOptions {
  /// Every new node gets this weak prior around its initial estimate so that L stays positive
  /// definite even before the node is observed (information 1/sigma^2 = 1e-8 /m^2: negligible).
  double regularization_sigma_m = 1e4;
  /// Gauss-Newton iterations over the persistent edges per Solve().
  int max_relinearization_iterations = 3;
  double relinearization_tolerance_m = 1e-4;
  /// When the sparse LDL^T factor of the last symbolic analysis filled more than this share of
  /// the dense lower triangle (agents marginalized out link every crumb they heard), the system
  /// is factorized as a dense matrix (blocked Cholesky) until the pattern changes. 1: never.
  double dense_fill_share = 0.5;
};

/// How one edge's observation moves with a consider parameter (GenNetwork::AddConsider): for a
/// linear edge dz/dtheta of its 2-vector z; for a scalar edge the derivative of its known
/// `offset` displacement.
struct ConsiderRate {
  int parameter = -1;
  Vec2 rate = Vec2::Zero();
};

class GenNetwork {
 public:
  explicit GenNetwork(GenOptions options = {});

  /// A consider parameter (Tapley, Schutz & Born 2004, sec. 6.3): a scalar error that some
  /// observations depend on but the network does not estimate (a PDR track's heading offset).
  /// Edges given its rate (ConsiderRate) add J^T W dz/dtheta to the derivative of b, which
  /// every marginalization carries like b; Solve() then gives each node's sensitivity
  /// d x_hat / d theta = L^-1 db/dtheta (first order at the solution; a persistent edge's
  /// observation does not move with it). Returns its index.
  int AddConsider() { return considers_++; }
  int considers() const { return considers_; }
  /// Node i's sensitivity to consider parameter c at the last successful Solve() (zero for a
  /// node added since, or when no edge moves with c). Computed for every parameter at once on
  /// the first call after a solve (one solve with the factor, C right-hand sides), so that a
  /// network solved more often than its covariances are read does not pay for it at each
  /// solve; while edges wait for the next Solve() the last values are returned.
  Vec2 Sensitivity(NodeIndex i, int c);
  /// Whether Sensitivity() would cost no solve (computed since the last Solve()).
  bool sensitivities_current() const { return !sensitivities_stale_ && !dirty_; }
  /// How often the sensitivities were solved for (each: C right-hand sides with the factor).
  std::size_t sensitivity_solves() const { return sensitivity_solves_; }

  /// AddNode, eq. (13): new zero rows/columns, plus the weak regularization prior unless
  /// `regularize` is false — a node that an edge to an existing node will hold at once (a
  /// mobile node's next state): marginalization would carry each such prior on, and N states
  /// would hold the walk with N times the "negligible" information.
  NodeIndex AddNode(const Vec2& initial_estimate, bool regularize = true);
  /// A Gaussian prior x_i ~ N(mean, cov): an edge to the ground (an anchor at `mean`), eq. (12).
  void AddPrior(NodeIndex i, const Vec2& mean, const Mat2& cov);
  /// AddMeasurement, eq. (11): zeta = x_i - x_j + e, e ~ N(0, cov).
  void AddRelative(NodeIndex i, NodeIndex j, const Vec2& zeta, const Mat2& cov,
                   const std::vector<ConsiderRate>& rates = {});
  /// The general linear edge of the information filter (eqs. (18)-(19) with a linear h):
  ///   z = sum_k J_k x_k + e,  e ~ N(0, cov),
  /// for any number of distinct nodes (e.g. a PDR displacement rotated and scaled by an agent's
  /// heading/scale node). AddRelative is the case J = (I, -I).
  void AddLinear(const std::vector<NodeIndex>& nodes, const std::vector<Mat2>& jacobians,
                 const Vec2& z, const Mat2& cov, const std::vector<ConsiderRate>& rates = {});
  /// Eq. (12): zeta = x_i - anchor + e with a known anchor position.
  void AddRelativeToAnchor(NodeIndex i, const Vec2& anchor, const Vec2& zeta, const Mat2& cov);
  /// AddMeasurement+, eqs. (18)-(19): z = h(|x_i - x_j + offset|) + e, e ~ N(0, variance),
  /// linearized at the current estimate. `offset` is a known displacement (e.g. the PDR
  /// displacement between the measurement time and the node's state time).
  /// `bias` (optional): a node (offset, scale) of the measurement, z = (1 + scale) h(d) + offset
  /// + e, e.g. a UWB radio's range offset and clock/propagation scale, estimated with the rest.
  /// `rates`: how `offset` moves with consider parameters.
  void AddScalar(NodeIndex i, NodeIndex j, double z, double variance, const ScalarModel& model,
                 const Vec2& offset = Vec2::Zero(), NodeIndex bias = -1,
                 const std::vector<ConsiderRate>& rates = {});
  /// The same with a known point instead of node j.
  void AddScalarToAnchor(NodeIndex i, const Vec2& anchor, double z, double variance,
                         const ScalarModel& model, const Vec2& offset = Vec2::Zero());
  /// A persistent scalar edge between two nodes (re-linearized at each Solve). Repeated
  /// measurements of the same edge should be accumulated with AccumulatePersistent.
  int AddPersistent(NodeIndex i, NodeIndex j, const ScalarModel& model);
  /// One scalar measurement kept as a persistent edge (AddScalar's model, offset, bias node and
  /// rates): re-linearized at every Solve (Gauss-Newton) until one of its nodes is deleted,
  /// then folded at the estimates of that moment. A fixed-lag smoother's window
  /// (LocalizerOptions::fixed_lag_s): an edge added while its nodes were far from the truth is
  /// re-linearized until the agent state it belongs to leaves (issue 25, item 2). The consider
  /// rates enter the sensitivities at the current linearization. Returns the edge's id.
  int AddScalarPersistent(NodeIndex i, NodeIndex j, double z, double variance,
                          const ScalarModel& model, const Vec2& offset = Vec2::Zero(),
                          NodeIndex bias = -1, const std::vector<ConsiderRate>& rates = {});
  /// Persistent edges not yet folded.
  std::size_t active_persistent() const { return active_persistent_; }
  bool IsPersistentActive(int edge) const {
    return edge >= 0 && edge < static_cast<int>(persistent_.size()) && persistent_[edge].active;
  }
  /// The persistent edge's nodes (i, j).
  std::pair<NodeIndex, NodeIndex> PersistentNodes(int edge) const {
    return {persistent_.at(edge).i, persistent_.at(edge).j};
  }
  /// Before a persistent edge is folded: its model's second-order terms at the current
  /// estimates and the covariance cov_m2 of the difference of its two positions
  /// (ScalarModel::SecondOrderTerms; scaled by the bias node's scale) — the observation shifted
  /// by the mean shift, the variance term added. Within the window the edge is re-linearized and
  /// needs none; committed, it stays linearized where it was, and the remaining uncertainty of
  /// its nodes biases it (LocalizerOptions::second_order).
  void AddSecondOrderTerms(int edge, const Mat2& cov_m2);
  /// Adds one measurement z with variance to persistent edge `edge` (information-weighted mean).
  /// The edge's variance is floor_variance + 1 / sum(1 / variance): a static link's slow
  /// shadowing does not average out over packets, only the fast fading does.
  void AccumulatePersistent(int edge, double z, double variance);
  void SetPersistentFloor(int edge, double floor_variance);
  /// Replaces the measurement model of a persistent edge (e.g. after a radio re-calibration).
  void SetPersistentModel(int edge, const ScalarModel& model);
  /// Scales the information of a persistent edge by w in (0, 1] (robust re-weighting).
  void SetPersistentWeight(int edge, double w);
  /// Normalized residual (z_bar - h(x_hat)) / sigma of a persistent edge at the estimate.
  double PersistentResidual(int edge) const;
  /// DeleteNode(+), eqs. (14)-(17): marginalizes node i out (Schur complement).
  void DeleteNode(NodeIndex i);
  /// Marginalizes two nodes at once (a mobile agent's old position and heading states): one
  /// Schur complement with a 4x4 pivot instead of two with fill in between.
  void DeleteNodes(NodeIndex a, NodeIndex b);
  /// Moves active node `from` into the free slot `to` (a mobile node's new state taking its
  /// deleted predecessor's slot keeps the sparsity pattern, so the symbolic analysis of the
  /// factorization is reused). Returns `to`.
  NodeIndex MoveNode(NodeIndex from, NodeIndex to);

  /// Solves L x = b (with Gauss-Newton over persistent edges). Cheap when nothing changed.
  /// Returns false (and keeps the previous estimate) if L is not positive definite.
  bool Solve();
  /// Current estimate (the initial estimate until the first Solve()).
  const Vec2& Estimate(NodeIndex i) const { return nodes_[i].x_hat; }
  /// Sets the linearization point of a node before measurements are added (e.g. after a
  /// delayed initialization). Does not change L or b.
  void SetEstimate(NodeIndex i, const Vec2& x) { nodes_[i].x_hat = x; }
  /// Marginal covariance Sigma_ii = (L^-1)_ii (solves with the current factor).
  Mat2 Covariance(NodeIndex i);
  /// Joint covariance of two nodes, 4x4.
  Eigen::Matrix4d JointCovariance(NodeIndex i, NodeIndex j);

  bool IsActive(NodeIndex i) const {
    return i >= 0 && i < static_cast<int>(nodes_.size()) && nodes_[i].active;
  }
  int active_nodes() const { return active_count_; }
  std::size_t off_diagonal_blocks() const;  ///< counted once per pair
  std::size_t factorizations() const { return factorizations_; }
  /// Largest system solved so far: its dimension and the non-zeros of its LDL^T factor.
  int max_dimension() const { return max_dimension_; }
  std::size_t max_factor_nonzeros() const { return max_factor_nonzeros_; }
  std::size_t symbolic_analyses() const { return analyses_; }
  std::size_t dense_factorizations() const { return dense_factorizations_; }
  bool dirty() const { return dirty_; }

  /// Dense L and b over the active nodes in slot order (tests, small graphs only); persistent
  /// edges linearized at the current estimate are included.
  void DenseSystem(Eigen::MatrixXd* L, Eigen::VectorXd* b, std::vector<NodeIndex>* order) const;

 private:
  struct Block {
    NodeIndex j;
    Mat2 L;
  };
  struct Node {
    bool active = false;
    Mat2 L_ii = Mat2::Zero();
    Vec2 b = Vec2::Zero();
    Vec2 x_hat = Vec2::Zero();
    std::vector<Block> off;           ///< L_ij, j != i
    std::vector<int> persistent;      ///< persistent edges touching the node
    int compact = -1;                 ///< index into the solver's vectors
    std::vector<Vec2> db;             ///< d b / d theta_c (shorter: zero beyond)
    std::vector<Vec2> sens;           ///< d x_hat / d theta_c at the last Solve()
  };
  /// Adds v to node i's d b / d theta_c.
  void AddRate(NodeIndex i, int c, const Vec2& v);
  /// L^-1 db for every consider parameter, with the current factor, into Node::sens.
  void SolveSensitivities();
  int considers_ = 0;
  bool sensitivities_stale_ = true;  ///< solved since Node::sens was computed
  std::size_t sensitivity_solves_ = 0;
  struct Persistent {
    NodeIndex i = -1, j = -1;
    NodeIndex bias = -1;              ///< (offset, scale) node of the measurement, -1: none
    Vec2 offset = Vec2::Zero();       ///< known displacement added to x_i
    std::vector<ConsiderRate> rates;  ///< how `offset` moves with consider parameters
    ScalarModel model;
    double information = 0;  ///< sum 1/var
    double weighted_z = 0;   ///< sum z/var
    double floor_variance = 0;
    double weight = 1.0;
    bool active = false;
    double Variance() const { return (floor_variance + 1.0 / information) / weight; }
    double Mean() const { return weighted_z / information; }
  };

  Mat2& OffBlock(NodeIndex i, NodeIndex j);  ///< creates when missing (pattern change)
  void AddLinearizedScalar(NodeIndex i, NodeIndex j, const Vec2& anchor, double z, double variance,
                           const ScalarModel& model, const Vec2& offset, NodeIndex bias = -1,
                           const std::vector<ConsiderRate>& rates = {});
  void FoldPersistent(int edge);
  /// One persistent scalar edge linearized at the current estimates (eqs. (18)-(19)): its
  /// nodes (i, j and the bias node when it has one) with their Jacobian rows (h w.r.t. x_i, -h
  /// for x_j), weight w = 1/variance and the linearized observation r, so the edge adds
  /// w row_a row_c^T to the Kirchhoff blocks and w row_a r to b.
  struct Linearized {
    std::array<NodeIndex, 3> nodes;
    std::array<Vec2, 3> rows;
    int n = 2;
    double w;
    double r;
  };
  Linearized LinearizePersistent(const Persistent& e) const;
  std::size_t active_persistent_ = 0;
  bool Factorize(const std::vector<Eigen::Triplet<double>>& extra_L);
  void CompactIndices();
  std::vector<std::pair<int, int>> BlockPattern() const;
  void FillReducingOrder();
  void PreparePattern();
  bool pattern_same_ = false;
  bool active_set_same_ = false;  ///< CompactIndices kept the numbering

  GenOptions options_;
  std::vector<Node> nodes_;
  std::vector<NodeIndex> free_;
  std::vector<Persistent> persistent_;
  int active_count_ = 0;
  bool pattern_dirty_ = true;
  bool dirty_ = true;
  std::vector<NodeIndex> order_;  ///< compact index -> slot
  /// Natural ordering: the compact numbering is already fill-reducing (FillReducingOrder).
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Lower, Eigen::NaturalOrdering<int>>
      solver_;
  Eigen::SparseMatrix<double> matrix_;
  bool factor_valid_ = false;
  std::vector<std::pair<int, int>> analysed_pattern_;  ///< block pattern of the last analysis
  // DeleteNode scratch (no allocation per marginalization)
  template <int K>
  void Marginalize(const std::array<NodeIndex, K>& nodes);
  std::vector<NodeIndex> scratch_neighbours_;
  std::vector<Mat2> scratch_fill_;
  std::vector<int> mark_;
  std::vector<int> row_pos_;  ///< Factorize scratch: row -> position in the current column
  // Marginals from the factor (MarginalOfRows)
  Eigen::MatrixXd MarginalOfRows(const std::vector<int>& rows);
  std::vector<int> etree_parent_;
  bool etree_valid_ = false;
  Eigen::MatrixXd work_;
  std::vector<char> visited_;
  std::vector<int> path_;
  std::size_t factorizations_ = 0;
  std::size_t analyses_ = 0;
  // The dense path (GenOptions::dense_fill_share): same compact numbering as the sparse one.
  bool FactorizeDense(int n, const std::vector<Eigen::Triplet<double>>& extra_L);
  bool dense_ = false;         ///< the current factor is dense_llt_ (else solver_)
  bool prefer_dense_ = false;  ///< the analysed pattern fills: factorize it dense
  Eigen::MatrixXd dense_A_;
  Eigen::LLT<Eigen::MatrixXd> dense_llt_;
  std::size_t dense_factorizations_ = 0;
  int max_dimension_ = 0;
  std::size_t max_factor_nonzeros_ = 0;
};

}  // namespace trailmark::breadcrumb
