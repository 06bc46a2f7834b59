// SPDX-License-Identifier: MIT
#include "trailmark/mapmatch/particle_filter.h"

#include <fmt/format.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <map>
#include <nanoflann.hpp>
#include <numbers>
#include <numeric>
#include <stdexcept>

#include "trailmark/integrity/consistency.h"

namespace trailmark::mapmatch {

struct MapParticleFilter::NodeIndex {
  std::vector<Vec2> points;
  std::vector<std::vector<std::pair<int, int>>> at;  ///< (sequence, node) per unique point
  // nanoflann dataset adaptor
  std::size_t kdtree_get_point_count() const { return points.size(); }
  double kdtree_get_pt(std::size_t i, std::size_t d) const {
    return points[i](static_cast<int>(d));
  }
  template <class Box>
  bool kdtree_get_bbox(Box&) const {
    return false;
  }
  using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, NodeIndex>,
                                                   NodeIndex, 2>;
  std::unique_ptr<Tree> tree;
  int Nearest(const Vec2& p) const {
    unsigned int index = 0;
    double d2 = 0;
    const double q[2] = {p.x(), p.y()};
    return tree->knnSearch(q, 1, &index, &d2) == 1 ? static_cast<int>(index) : -1;
  }
};

bool MapParticleFilterOptions::IsValid(std::string* why) const {
  auto fail = [&](const char* w) {
    if (why) *why = w;
    return false;
  };
  if (particles < 10 || particles > 1000000)
    return fail("particles must be within 10 .. 1,000,000");
  if (!(position_noise_m >= 0) || !(heading_noise_rad_per_m >= 0))
    return fail("noises must be >= 0");
  if (!(likelihood_sigma > 0)) return fail("likelihood_sigma must be > 0");
  if (!(tracking_likelihood_sigma >= 0))
    return fail("tracking_likelihood_sigma must be >= 0 (0: likelihood_sigma throughout)");
  if (!(weight_floor >= 0 && weight_floor < 1)) return fail("weight_floor must be within [0, 1)");
  if (!(outlier_weight >= 0 && outlier_weight < 1))
    return fail("outlier_weight must be within [0, 1)");
  if (!(resample_fraction >= 0 && resample_fraction <= 1))
    return fail("resample_fraction must be within [0, 1]");
  if (!(resample_position_sigma_m >= 0) || !(resample_heading_sigma_rad >= 0))
    return fail("resample noises >= 0");
  if (!(relocalize_above_variance_m2 >= 0) || !(known_start_relocalize_above_variance_m2 >= 0))
    return fail(
        "relocalize_above_variance_m2 and known_start_relocalize_above_variance_m2 must be >= 0");
  if (!(wall_alarm_k >= 0 && wall_alarm_k < 1) || !(wall_alarm_h > 0))
    return fail("wall_alarm_k must be within [0, 1) and wall_alarm_h > 0");
  if (!(recover_position_sigma_m >= 0) || !(recover_heading_sigma_rad >= 0) ||
      recover_pattern_updates < 0 || confirm_pattern_updates < 0)
    return fail(
        "recovery spreads, recover_pattern_updates and confirm_pattern_updates must be >= 0");
  if (!(max_match_rmse_m > 0)) return fail("max_match_rmse_m must be > 0");
  if (!(confirm_distinct_m >= 0)) return fail("confirm_distinct_m must be >= 0 (0: off)");
  if (!(wall_follow_offset_m >= 0 && wall_follow_offset_m <= 2) || !(wall_follow_sigma_m > 0))
    return fail("wall_follow_offset_m must be within [0, 2] and wall_follow_sigma_m > 0");
  if (!(wall_follow_leave > 0 && wall_follow_leave < 1) ||
      !(wall_follow_return > 0 && wall_follow_return <= 1) ||
      !(wall_follow_off_likelihood > 0 && wall_follow_off_likelihood <= 1) ||
      !(wall_follow_converged_power >= 0 && wall_follow_converged_power <= 1) ||
      !(stated_wall_follow_converged_power >= 0 && stated_wall_follow_converged_power <= 1))
    return fail(
        "wall_follow_leave must be within (0, 1), wall_follow_return and "
        "wall_follow_off_likelihood within (0, 1], wall_follow_converged_power and its stated_ "
        "within [0, 1]");
  if (!(free_walk_share >= 0 && free_walk_share < 1) ||
      !(free_walk_switch >= 0 && free_walk_switch <= 1))
    return fail("free_walk_share must be within [0, 1), free_walk_switch within [0, 1]");
  if (!(kld_epsilon >= 0 && kld_epsilon < 1))
    return fail("kld_epsilon must be within [0, 1) (0: off)");
  if (!(kld_quantile > 0.5 && kld_quantile < 1))
    return fail("kld_quantile must be within (0.5, 1)");
  if (!(kld_bin_m > 0) || !(kld_bin_rad > 0) || !std::isfinite(kld_bin_m) ||
      !std::isfinite(kld_bin_rad))
    return fail("kld_bin_m and kld_bin_rad must be > 0");
  if (kld_min_particles < 10 || kld_min_particles > particles)
    return fail("kld_min_particles must be within 10 .. particles");
  return true;
}

std::string MapParticleFilterSummary::BriefReport() const {
  return fmt::format(
      "map particle filter: {} time / {} pattern updates ({} uninformative, {} not distinctive), "
      "{} wall eliminations, "
      "{} floor "
      "replacements, {} particles from patterns, {} systematic resamples, {} backtracks, {} "
      "restarts; {} "
      "comparisons skipped while converged; {} left the building; particles {} now ({} .. {}), "
      "{} particle-steps",
      time_updates, pattern_updates, uninformative_updates, ambiguous_updates, wall_eliminations,
      floor_replacements, pattern_resamples, systematic_resamples, backtracks, restarts,
      skipped_converged, outside_eliminations, particles_now, particles_min, particles_max,
      particle_steps);
}

double KldSampleSize(int occupied_bins, double epsilon, double quantile) {
  if (occupied_bins <= 1) return 1.0;
  return integrity::ChiSquareQuantile(occupied_bins - 1, quantile) / (2 * epsilon);
}

MapParticleFilter::MapParticleFilter(const SearchGrid& grid,
                                     const std::vector<NodeSequence>& sequences, Options options,
                                     std::shared_ptr<const DistanceField> wall_distance)
    : grid_(grid),
      sequences_(sequences),
      options_(options),
      rng_(options.seed),
      nodes_(new NodeIndex),
      wall_distance_(std::move(wall_distance)) {
  std::string why;
  if (!options_.IsValid(&why)) throw std::invalid_argument("MapParticleFilter options: " + why);
  inside_centers_ = grid.InsideCenters();
  if (inside_centers_.empty())
    throw std::invalid_argument("MapParticleFilter: the floor plan encloses no area");
  for (const Vec2& c : inside_centers_) inside_mean_ += c, inside_second_ += c * c.transpose();
  inside_mean_ /= static_cast<double>(inside_centers_.size());
  inside_second_ /= static_cast<double>(inside_centers_.size());
  std::map<std::pair<long, long>, int> unique;
  for (int m = 0; m < static_cast<int>(sequences.size()); ++m) {
    for (int n = 0; n < static_cast<int>(sequences[m].nodes.size()); ++n) {
      const Vec2& p = sequences[m].nodes[n];
      const auto key = std::make_pair(std::lround(p.x() * 1000), std::lround(p.y() * 1000));
      auto it = unique.find(key);
      if (it == unique.end()) {
        it = unique.emplace(key, static_cast<int>(nodes_->points.size())).first;
        nodes_->points.push_back(p);
        nodes_->at.emplace_back();
      }
      nodes_->at[it->second].emplace_back(m, n);
    }
  }
  nodes_->tree =
      std::make_unique<NodeIndex::Tree>(2, *nodes_, nanoflann::KDTreeSingleIndexAdaptorParams(8));
  particles_.resize(options_.particles);
  NoteParticleCount();
  if (options_.wall_follow && !wall_distance_)
    wall_distance_ = MakeWallDistanceField(grid.plan(), grid.axis_rad());
}

MapParticleFilter::~MapParticleFilter() = default;

bool MapParticleFilter::InsideBuilding(const Vec2& p) const {
  if (options_.exact_inside) return grid_.Contains(p);
  return std::isfinite(p.x()) && std::isfinite(p.y()) && grid_.Inside(grid_.CellOf(p));
}

Vec2 MapParticleFilter::GridNoise(double sigma_m) {
  // Drawn in the grid's axes, so that a plan drawn rotated gets the same draws (issue 23).
  return grid_.ToNavigation(Vec2(rng_.Normal(0, sigma_m), rng_.Normal(0, sigma_m)));
}

Vec2 MapParticleFilter::RandomInsidePoint() {
  const Vec2& c = inside_centers_[std::min(
      inside_centers_.size() - 1, static_cast<std::size_t>(Uniform() * inside_centers_.size()))];
  const double h = 0.5 * grid_.spacing();
  return c + grid_.ToNavigation(Vec2(rng_.Uniform(-h, h), rng_.Uniform(-h, h)));
}

void MapParticleFilter::UseSharedErrors(const SharedStepErrorPrior& prior) { shared_ = prior; }

void MapParticleFilter::DrawSharedErrors(Particle& q) {
  if (!shared_) return;  // the paper's random stream
  q.step_scale = static_cast<float>(rng_.Normal(0, shared_->step_scale_sigma));
  q.turn_scale = static_cast<float>(rng_.Normal(0, shared_->turn_scale_sigma));
  q.drift_rad_per_s = static_cast<float>(rng_.Normal(0, shared_->heading_drift_sigma_rad_per_s));
}

void MapParticleFilter::InitializeKnown(const Vec2& p, double offset, double ps, double hs) {
  particles_.resize(options_.particles);
  NoteParticleCount();
  uniform_start_ = false;
  converged_ = false;
  tracking_ = false;
  wall_cusum_ = 0;
  forced_pattern_updates_ = 0;
  for (auto& q : particles_) {
    q.position_n = p + GridNoise(ps);
    q.heading_offset_rad = offset + rng_.Normal(0, hs);
    q.hand = RandomHand();
    DrawSharedErrors(q);
    q.p_off_wall = 0;
    q.step_from_n = q.position_n;
    q.weight = 1.0 / particles_.size();
  }
}

void MapParticleFilter::InitializeUniform() {
  particles_.resize(options_.particles);
  NoteParticleCount();
  uniform_start_ = true;
  pattern_updates_applied_ = 0;
  converged_ = false;
  tracking_ = false;
  wall_cusum_ = 0;
  forced_pattern_updates_ = 0;
  for (auto& q : particles_) {
    q.position_n = q.step_from_n = RandomInsidePoint();
    q.heading_offset_rad = rng_.Uniform(-std::numbers::pi, std::numbers::pi);
    q.hand = RandomHand();
    q.p_off_wall = 0;
    DrawSharedErrors(q);
    q.weight = 1.0 / particles_.size();
  }
}

void MapParticleFilter::ContinueFrom(const MapParticleFilter& from,
                                     const std::vector<char>& keep) {
  if (keep.size() != from.particles_.size()) {
    throw std::invalid_argument("ContinueFrom: keep has another size than the particles");
  }
  uniform_start_ = from.uniform_start_;
  converged_ = from.converged_;
  tracking_ = from.tracking_;
  pattern_updates_applied_ = from.pattern_updates_applied_;
  forced_pattern_updates_ = from.forced_pattern_updates_;
  wall_cusum_ = 0;
  last_blocked_mass_ = 0;
  last_step_alarm_ = false;
  particles_ = from.particles_;
  NoteParticleCount();
  for (auto& q : particles_) q.step_from_n = q.position_n;
  std::vector<char> dead(keep.size());
  bool any = false;
  for (std::size_t i = 0; i < keep.size(); ++i) {
    dead[i] = keep[i] ? 0 : 1;
    any = any || (keep[i] && particles_[i].weight > 0);
  }
  if (any) ReplaceFromSurvivors(dead);
  GrowToMaximum();  // KLD-sampling: a change of level is a moment of doubt
}

std::uint8_t MapParticleFilter::RandomHand() {
  // Only the wall-following model reads the hand: without it, no draw (the random stream, and
  // so the results, stay those of the paper's filter).
  if (!options_.wall_follow) return 0;
  const double u = Uniform();
  const double f = options_.free_walk_share;
  if (u < f) return 2;
  return (u - f) / (1 - f) >= 0.5 ? 1 : 0;
}

void MapParticleFilter::Normalize() {
  double sum = 0;
  for (const auto& q : particles_) sum += q.weight;
  if (!(sum > 0) || !std::isfinite(sum)) {
    for (auto& q : particles_) q.weight = 1.0 / particles_.size();
    return;
  }
  for (auto& q : particles_) q.weight /= sum;
}

int MapParticleFilter::DrawSurvivor(const std::vector<double>& cdf, const std::vector<int>& alive) {
  const double u = Uniform() * cdf.back();
  const auto k =
      std::min(static_cast<std::size_t>(std::lower_bound(cdf.begin(), cdf.end(), u) - cdf.begin()),
               alive.size() - 1);
  return alive[k];
}

void MapParticleFilter::ReplaceFromSurvivors(const std::vector<char>& dead) {
  std::vector<double> cdf;
  std::vector<int> alive;
  double acc = 0;
  for (int i = 0; i < static_cast<int>(particles_.size()); ++i) {
    if (dead[i]) continue;
    acc += particles_[i].weight;
    cdf.push_back(acc);
    alive.push_back(i);
  }
  if (alive.empty() || !(acc > 0)) {
    // Every particle hit a wall: start again (uniform, or around the last mean).
    ++summary_.restarts;
    if (uniform_start_) tracking_ = false;  // the track is to be found again
    const Vec2 mean = Mean();
    particles_.resize(options_.particles);  // KLD-sampling: a restart takes every particle
    NoteParticleCount();
    for (auto& q : particles_) {
      q.position_n = uniform_start_ ? RandomInsidePoint() : mean + GridNoise(1.0);
      q.step_from_n = q.position_n;  // a new particle, not a step
      if (uniform_start_) {
        q.heading_offset_rad = rng_.Uniform(-std::numbers::pi, std::numbers::pi);
        q.hand = RandomHand();
        q.p_off_wall = 0;
        DrawSharedErrors(q);
      }
      q.weight = 1.0 / particles_.size();
    }
    return;
  }
  for (int i = 0; i < static_cast<int>(particles_.size()); ++i) {
    if (!dead[i]) continue;
    particles_[i] = particles_[DrawSurvivor(cdf, alive)];
  }
  Normalize();
}

void MapParticleFilter::ReplaceWithinModels(const std::vector<char>& dead) {
  // Per model (0: searching, 1: free walking): its survivors' running weight and indices.
  std::vector<double> cdf[2];
  std::vector<int> alive[2];
  double acc[2] = {0, 0}, mass[2] = {0, 0};
  for (int i = 0; i < static_cast<int>(particles_.size()); ++i) {
    const int c = particles_[i].hand == 2 ? 1 : 0;
    mass[c] += particles_[i].weight;
    if (dead[i]) continue;
    acc[c] += particles_[i].weight;
    cdf[c].push_back(acc[c]);
    alive[c].push_back(i);
  }
  const bool has[2] = {acc[0] > 0, acc[1] > 0};
  if (!has[0] && !has[1]) {
    ReplaceFromSurvivors(dead);  // every particle hit a wall: the restart
    return;
  }
  for (int i = 0; i < static_cast<int>(particles_.size()); ++i) {
    if (!dead[i]) continue;
    int c = particles_[i].hand == 2 ? 1 : 0;
    if (!has[c]) c = 1 - c;  // a model with no survivor continues from the other's
    particles_[i] = particles_[DrawSurvivor(cdf[c], alive[c])];
  }
  // Each model with survivors keeps the belief it had before the step: the walls weigh the
  // particles within a model, not the models against each other (a free walker's particles
  // diffuse into walls that the searcher's prior keeps its particles away from).
  double now[2] = {0, 0};
  for (const auto& q : particles_) now[q.hand == 2 ? 1 : 0] += q.weight;
  for (auto& q : particles_) {
    const int c = q.hand == 2 ? 1 : 0;
    if (has[0] && has[1] && now[c] > 0) q.weight *= mass[c] / now[c];
  }
  Normalize();
}

void MapParticleFilter::ResampleIfDegenerate() {
  double sum2 = 0;
  for (const auto& q : particles_) sum2 += q.weight * q.weight;
  if (1.0 / sum2 < options_.ess_resample_fraction * particles_.size()) SystematicResample();
}

void MapParticleFilter::SystematicResample() {
  const bool kld = options_.kld_epsilon > 0;
  // With KLD-sampling the draw is made at the most particles first: its histogram says how
  // many the belief needs; then that many are taken from it, evenly spaced (the draw is in
  // the cumulative weight's order, so this is a systematic resampling to that number).
  const std::size_t n = kld ? static_cast<std::size_t>(options_.particles) : particles_.size();
  std::vector<Particle> out = DrawSystematic(n);
  ++summary_.systematic_resamples;
  if (kld) {
    const double wanted =
        KldSampleSize(OccupiedBins(out), options_.kld_epsilon, options_.kld_quantile);
    const auto m = static_cast<std::size_t>(std::clamp<double>(
        std::ceil(wanted), options_.kld_min_particles, static_cast<double>(options_.particles)));
    if (m < n) {
      std::vector<Particle> fewer(m);
      const double stride = static_cast<double>(n) / m;
      const double start = Uniform() * stride;
      for (std::size_t i = 0; i < m; ++i) {
        fewer[i] = out[std::min(n - 1, static_cast<std::size_t>(start + i * stride))];
        fewer[i].weight = 1.0 / m;
      }
      out = std::move(fewer);
    }
  }
  particles_ = std::move(out);
  NoteParticleCount();
}

void MapParticleFilter::GrowToMaximum() {
  const auto most = static_cast<std::size_t>(options_.particles);
  if (particles_.size() >= most) return;
  // Copies of the particles drawn by weight (a systematic draw), each with weight 1 / N: a
  // belief about to be spread needs every particle, whatever its histogram says now.
  Normalize();
  particles_ = DrawSystematic(most);
  NoteParticleCount();
}

std::vector<MapParticleFilter::Particle> MapParticleFilter::DrawSystematic(std::size_t n) {
  std::vector<Particle> out(n);
  const double step = 1.0 / n;
  double u = Uniform() * step, acc = particles_[0].weight;
  std::size_t k = 0;
  for (std::size_t i = 0; i < n; ++i) {
    while (u > acc && k + 1 < particles_.size()) acc += particles_[++k].weight;
    out[i] = particles_[k];
    out[i].weight = step;
    u += step;
  }
  return out;
}

int MapParticleFilter::OccupiedBins(const std::vector<Particle>& particles) const {
  // Bins along the grid's axes and of the heading offset from the grid's axis, so that a plan
  // drawn rotated or shifted gets the same histogram.
  std::vector<std::uint64_t> keys;
  keys.reserve(particles.size());
  for (const Particle& q : particles) {
    const Vec2 g = grid_.ToGrid(q.position_n) / options_.kld_bin_m;
    const double h = WrapAngle(q.heading_offset_rad - grid_.axis_rad()) + std::numbers::pi;
    const auto ix =
        static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(g.x())) & 0xFFFFF);
    const auto iy =
        static_cast<std::uint64_t>(static_cast<std::int64_t>(std::floor(g.y())) & 0xFFFFF);
    const auto ih = static_cast<std::uint64_t>(std::floor(h / options_.kld_bin_rad)) & 0x3FFF;
    keys.push_back((ix << 44) | (iy << 24) | (ih << 2) | (q.hand & 3u));
  }
  std::sort(keys.begin(), keys.end());
  return static_cast<int>(std::unique(keys.begin(), keys.end()) - keys.begin());
}

void MapParticleFilter::NoteParticleCount() {
  const std::size_t n = particles_.size();
  summary_.particles_now = n;
  summary_.particles_min = summary_.particles_min == 0 ? n : std::min(summary_.particles_min, n);
  summary_.particles_max = std::max(summary_.particles_max, n);
}

void MapParticleFilter::Predict(const Vec2& d, const StatedStep* stated) {
  ++summary_.time_updates;
  summary_.particle_steps += particles_.size();
  NoteConvergence();
  const double len = d.norm();
  const FloorPlan& plan = grid_.plan();
  before_step_ = particles_;  // the scratch keeps its capacity: no allocation per step
  const std::vector<Particle>& before = before_step_;
  // When every particle hits a wall, the step is tried again from the same particles with
  // wider noise (a backtracking step, cf. Widyawan et al. 2008) before giving up.
  for (int attempt = 0; attempt < 4; ++attempt) {
    const double widen = 1.0 + 1.5 * attempt;
    if (attempt > 0) {
      particles_ = before;
      ++summary_.backtracks;
    }
    std::vector<char>& dead = dead_;
    dead.assign(particles_.size(), 0);
    std::size_t n_dead = 0;
    double mass_dead = 0, mass = 0;
    for (std::size_t i = 0; i < particles_.size(); ++i) {
      auto& q = particles_[i];
      mass += q.weight;
      q.step_from_n = q.position_n;
      Vec2 next;
      if (stated != nullptr) {
        // As the dead reckoning's error propagates (ins/dead_reckoning.cpp, AddStep): the
        // heading error grows by the drift rate x the time and the gyro scale x the turn, the
        // step is turned by it and stretched by the scale, its end moved by its own noise; then
        // the heading takes the step's own random walk.
        const double heading_rad = q.heading_offset_rad + q.turn_scale * stated->turn_rad +
                                   q.drift_rad_per_s * stated->dt_s;
        next = q.position_n + (1.0 + q.step_scale) * (Eigen::Rotation2Dd(heading_rad) * d) +
               GridNoise(widen * stated->position_sigma_m);
        q.heading_offset_rad =
            WrapAngle(heading_rad + rng_.Normal(0, widen * stated->heading_sigma_rad));
      } else {
        const double ps = widen * options_.position_noise_m;
        next = q.position_n + Eigen::Rotation2Dd(q.heading_offset_rad) * d + GridNoise(ps);
        q.heading_offset_rad = WrapAngle(
            q.heading_offset_rad + rng_.Normal(0, widen * options_.heading_noise_rad_per_m * len));
      }
      if (plan.Crosses(q.position_n, next)) {
        dead[i] = 1;
        ++n_dead;
        mass_dead += q.weight;
      }
      q.position_n = next;
    }
    summary_.wall_eliminations += n_dead;
    // A search stays in the building: a particle that left it (through a door that the map
    // shows open, e.g. the entry) is eliminated too, unless the whole belief left (then the
    // walker did).
    if (options_.stay_inside) {
      std::vector<std::size_t> outside;
      for (std::size_t i = 0; i < particles_.size(); ++i) {
        if (!dead[i] && !InsideBuilding(particles_[i].position_n)) outside.push_back(i);
      }
      if (!outside.empty() && n_dead + outside.size() < particles_.size()) {
        for (const std::size_t i : outside) dead[i] = 1;
        n_dead += outside.size();
        summary_.outside_eliminations += outside.size();
      }
    }
    // The first attempt's share says how much of the belief the walk drove into walls.
    if (attempt == 0) {
      last_blocked_mass_ = mass > 0 ? mass_dead / mass : 0.0;
      wall_cusum_ = std::max(0.0, wall_cusum_ + last_blocked_mass_ - options_.wall_alarm_k);
      last_step_alarm_ = wall_cusum_ > options_.wall_alarm_h;
      if (last_step_alarm_) {
        wall_cusum_ = 0;
        ++summary_.wall_alarms;
      }
    }
    if (n_dead < particles_.size() || attempt == 3) {
      if (n_dead > 0) {
        if (options_.wall_follow && options_.free_walk_share > 0)
          ReplaceWithinModels(dead);
        else
          ReplaceFromSurvivors(dead);
      }
      if (options_.wall_follow && len > 0.1) {
        // Full weight while uncertain; once converged, tempered (see the option).
        const bool uncertain =
            forced_pattern_updates_ > 0 || TriggerVariance() > PatternThreshold();
        const double power = uncertain           ? 1.0
                             : stated != nullptr ? options_.stated_wall_follow_converged_power
                                                 : options_.wall_follow_converged_power;
        if (power > 0) WeighWallFollowing(std::atan2(d.y(), d.x()), power);
      }
      if (last_step_alarm_ && options_.recover_on_wall_alarm && options_.pseudo_observations)
        Recover();
      return;
    }
  }
}

void MapParticleFilter::UpdatePatterns(const PatternComparison& pc, double odometry_heading_rad) {
  if (!options_.pseudo_observations) return;
  ++summary_.pattern_updates;
  const double s2 = options_.likelihood_sigma * options_.likelihood_sigma;
  // E of the observation each particle takes: its nearest node, the end whose heading is
  // closest to the particle's walking heading.
  auto observed_rmse = [&](const Particle& q) {
    const int u = nodes_->Nearest(q.position_n);
    if (u < 0) return std::numeric_limits<double>::infinity();
    const double heading = q.heading_offset_rad + odometry_heading_rad;
    double best_dh = 1e300, e = std::numeric_limits<double>::infinity();
    for (const auto& [m, n] : nodes_->at[u]) {
      const SequenceComparison& sc = pc.sequences[m];
      // As the first node of pattern n (left-hand end) ...
      const double dh1 = std::abs(WrapAngle(sc.heading_rad[n][0] - heading));
      if (dh1 < best_dh) best_dh = dh1, e = sc.rmse_m[n][0];
      // ... and as the last node of every pattern ending here (right-hand end).
      for (int eta = 0; eta < static_cast<int>(sc.last_node.size()); ++eta) {
        if (sc.last_node[eta] != n) continue;
        const double dh2 = std::abs(WrapAngle(sc.heading_rad[eta][1] - heading));
        if (dh2 < best_dh) best_dh = dh2, e = sc.rmse_m[eta][1];
      }
    }
    return e;
  };
  std::vector<double> E(particles_.size());
  double e_min = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < particles_.size(); ++i) {
    E[i] = observed_rmse(particles_[i]);
    e_min = std::min(e_min, E[i]);
  }
  double best_anywhere = std::numeric_limits<double>::infinity();
  for (const auto& sc : pc.sequences) {
    for (const auto& r : sc.rmse_m) best_anywhere = std::min({best_anywhere, r[0], r[1]});
  }
  const bool converged_now = TriggerVariance() <= PatternThreshold();
  if (forced_pattern_updates_ > 0) {
    --forced_pattern_updates_;
  } else if (converged_now && !AwaitingConfirmation()) {
    ++summary_.skipped_converged;
    return;
  }
  // After a recovery, once the particles have settled again, a comparison only offers new
  // particles: weighting the settled ones by one comparison (sigma 0.1) can wipe out the right
  // hypothesis when furniture makes a wrong match slightly better.
  const bool reweight = !(converged_now && !options_.recover_reweight_converged);
  if (!(best_anywhere <= options_.max_match_rmse_m)) {
    ++summary_.uninformative_updates;  // not a search pattern: no weights, no new particles
    return;
  }
  if (Distinctive(pc, best_anywhere)) {
    ++pattern_updates_applied_;
  } else {
    ++summary_.ambiguous_updates;
  }
  if (!std::isfinite(e_min)) {
    ++summary_.uninformative_updates;
  } else if (reweight) {
    // Eq. (2)-(3), scaled by exp(E_min / sigma^2) against underflow (cancels in eq. 3); once
    // the track has been found, with the tracking sigma (see the option).
    const double sigma = tracking_ && options_.tracking_likelihood_sigma > 0
                             ? options_.tracking_likelihood_sigma
                             : options_.likelihood_sigma;
    const double s2_weight = sigma * sigma;
    for (std::size_t i = 0; i < particles_.size(); ++i) {
      const double l = std::isfinite(E[i]) ? std::exp(-(E[i] - e_min) / s2_weight) : 0.0;
      particles_[i].weight *= options_.outlier_weight + (1 - options_.outlier_weight) * l;
    }
    Normalize();
    const double eps = options_.weight_floor / particles_.size();
    std::vector<char> low(particles_.size(), 0);
    int n_low = 0;
    for (std::size_t i = 0; i < particles_.size(); ++i) {
      if (particles_[i].weight < eps) low[i] = 1, ++n_low;
    }
    summary_.floor_replacements += n_low;
    if (n_low > 0 && n_low < static_cast<int>(particles_.size())) ReplaceFromSurvivors(low);
  }
  // Resampling from the pseudo observations: the q lowest-weight particles are redrawn.
  if (options_.resample_from_patterns && options_.resample_fraction > 0) {
    struct Obs {
      Vec2 p;
      double heading;
      double cumulative;
      int end;  ///< 0: a left-hand observation, 1: a right-hand one
    };
    std::vector<Obs> obs;
    double acc = 0, best = std::numeric_limits<double>::infinity();
    for (const auto& sc : pc.sequences) {
      for (const auto& r : sc.rmse_m) best = std::min({best, r[0], r[1]});
    }
    if (std::isfinite(best)) {
      for (const auto& sc : pc.sequences) {
        for (std::size_t n = 0; n < sc.rmse_m.size(); ++n) {
          for (int end = 0; end < 2; ++end) {
            if (!std::isfinite(sc.rmse_m[n][end])) continue;
            const double w = std::exp(-(sc.rmse_m[n][end] - best) / s2);
            if (w < 1e-12) continue;
            acc += w;
            obs.push_back({sc.position_n[n][end], sc.heading_rad[n][end], acc, end});
          }
        }
      }
    }
    if (!obs.empty()) {
      std::vector<std::size_t> order(particles_.size());
      std::iota(order.begin(), order.end(), 0);
      const std::size_t count =
          static_cast<std::size_t>(options_.resample_fraction * particles_.size());
      std::partial_sort(order.begin(), order.begin() + count, order.end(),
                        [&](std::size_t a, std::size_t b) {
                          return particles_[a].weight < particles_[b].weight;
                        });
      // A new particle starts with a small weight (ours; the paper does not say): it must earn
      // its share at the next comparisons instead of pulling the estimate at once.
      const double new_weight = options_.new_particle_weight / particles_.size();
      for (std::size_t k = 0; k < count; ++k) {
        const double u = Uniform() * acc;
        const auto it = std::lower_bound(obs.begin(), obs.end(), u,
                                         [](const Obs& o, double v) { return o.cumulative < v; });
        const Obs& o = it == obs.end() ? obs.back() : *it;
        Particle& q = particles_[order[k]];
        for (int attempt = 0; attempt < 10; ++attempt) {
          q.position_n = o.p + GridNoise(options_.resample_position_sigma_m);
          if (InsideBuilding(q.position_n)) break;
          q.position_n = o.p;
        }
        q.step_from_n = q.position_n;  // a new particle, not a step
        q.heading_offset_rad = WrapAngle(o.heading - odometry_heading_rad +
                                         rng_.Normal(0, options_.resample_heading_sigma_rad));
        q.weight = new_weight;
        q.hand = options_.wall_follow && options_.free_walk_share > 0 &&
                         Uniform() < options_.free_walk_share
                     ? 2
                     : static_cast<std::uint8_t>(o.end);
        q.p_off_wall = 0;
        DrawSharedErrors(q);
        ++summary_.pattern_resamples;
      }
      Normalize();
    }
  }
  ResampleIfDegenerate();
}

bool MapParticleFilter::WantsPatterns() const {
  return options_.pseudo_observations && (forced_pattern_updates_ > 0 || AwaitingConfirmation() ||
                                          TriggerVariance() > PatternThreshold());
}

bool MapParticleFilter::Distinctive(const PatternComparison& pc, double best_rmse_m) const {
  if (!(options_.confirm_distinct_m > 0)) return true;
  // The matches within 3 sigma^2 of the best, about their mean (not about the best one: two
  // matches equal to the last bits would make the answer depend on rounding).
  const double within = best_rmse_m + 3 * options_.likelihood_sigma * options_.likelihood_sigma;
  Vec2 sum = Vec2::Zero();
  std::size_t count = 0;
  auto for_each_good = [&](auto&& f) {
    for (const auto& sc : pc.sequences) {
      for (std::size_t n = 0; n < sc.rmse_m.size(); ++n) {
        for (int end = 0; end < 2; ++end) {
          if (sc.rmse_m[n][end] <= within) f(sc.position_n[n][end]);
        }
      }
    }
  };
  for_each_good([&](const Vec2& p) { sum += p, ++count; });
  if (count == 0) return false;
  const Vec2 mean = sum / static_cast<double>(count);
  bool close = true;
  for_each_good(
      [&](const Vec2& p) { close = close && (p - mean).norm() <= options_.confirm_distinct_m; });
  return close;
}

bool MapParticleFilter::Unconfirmed() const {
  return uniform_start_ && pattern_updates_applied_ < options_.confirm_pattern_updates;
}

double WallFollowingLikelihood(const DistanceField& walls, const Vec2& position_n,
                               double heading_n_rad, bool left_hand,
                               const MapParticleFilterOptions& o, float& p_off_wall) {
  // Where the wall should be: the offset to the search side of the walking direction.
  const double side = left_hand ? 1.0 : -1.0;
  const Vec2 at = position_n + side * o.wall_follow_offset_m *
                                   Vec2(-std::sin(heading_n_rad), std::cos(heading_n_rad));
  const double dd = walls.At(at);
  // One step of the forward recursion of the on/off-wall chain.
  const double prior_off =
      p_off_wall * (1 - o.wall_follow_return) + (1 - p_off_wall) * o.wall_follow_leave;
  const double l_on = std::exp(-dd * dd / (2 * o.wall_follow_sigma_m * o.wall_follow_sigma_m));
  const double l = (1 - prior_off) * l_on + prior_off * o.wall_follow_off_likelihood;
  p_off_wall = static_cast<float>(prior_off * o.wall_follow_off_likelihood / l);
  return l;
}

std::shared_ptr<const DistanceField> MakeWallDistanceField(const FloorPlan& plan, double axis_rad) {
  DistanceField::Options o;
  o.axis_rad = axis_rad;
  o.cell_m = 0.1;
  o.max_distance_m = 2.0;
  return std::make_shared<const DistanceField>(plan.solid_walls(), o);
}

void MapParticleFilter::WeighWallFollowing(double step_heading_odometry_rad, double power) {
  const double f = options_.free_walk_share;
  if (f > 0) {
    // The walker's model as a slowly switching hidden state (its stationary share is f).
    const double to_free = options_.free_walk_switch * f;
    const double to_search = options_.free_walk_switch * (1 - f);
    for (auto& q : particles_) {
      const double u = Uniform();
      if (q.hand == 2 && u < to_search) {
        q.hand = u < 0.5 * to_search ? 0 : 1;
        q.p_off_wall = 0;
      } else if (q.hand != 2 && u < to_free) {
        q.hand = 2;
      }
    }
  }
  double searching_before = 0, searching_after = 0;
  for (auto& q : particles_) {
    if (q.hand == 2) continue;  // a free walker: no wall to follow
    searching_before += q.weight;
    const double l = WallFollowingLikelihood(*wall_distance_, q.position_n,
                                             q.heading_offset_rad + step_heading_odometry_rad,
                                             q.hand == 0, options_, q.p_off_wall);
    q.weight *= power == 1.0 ? l : std::pow(l, power);
    searching_after += q.weight;
  }
  // With free walkers, a prior within the searching model: it moves no belief between models.
  if (f > 0 && searching_after > 0) {
    const double scale = searching_before / searching_after;
    for (auto& q : particles_) {
      if (q.hand != 2) q.weight *= scale;
    }
  }
  Normalize();
  ResampleIfDegenerate();
}

void MapParticleFilter::Recover() {
  ++summary_.recoveries;
  GrowToMaximum();  // KLD-sampling: a belief to be spread takes every particle
  for (auto& q : particles_) {
    const Vec2 p = q.position_n + GridNoise(options_.recover_position_sigma_m);
    if (InsideBuilding(p)) q.position_n = p;
    q.step_from_n = q.position_n;  // moved by the recovery, not by a step
    q.heading_offset_rad =
        WrapAngle(q.heading_offset_rad + rng_.Normal(0, options_.recover_heading_sigma_rad));
  }
  forced_pattern_updates_ = options_.recover_pattern_updates;
  converged_ = false;
}

double MapParticleFilter::PatternThreshold() const {
  if (!converged_) return options_.use_patterns_above_variance_m2;
  const double relocalize = uniform_start_
                                ? options_.relocalize_above_variance_m2
                                : std::max(options_.relocalize_above_variance_m2,
                                           options_.known_start_relocalize_above_variance_m2);
  return std::max(options_.use_patterns_above_variance_m2, relocalize);
}

void MapParticleFilter::NoteConvergence() {
  if (!converged_ && options_.use_patterns_above_variance_m2 > 0 && !AwaitingConfirmation() &&
      TriggerVariance() <= options_.use_patterns_above_variance_m2) {
    converged_ = true;
    tracking_ = true;
  }
}

Mat2 MapParticleFilter::ReportedCovariance() const {
  Mat2 c = Covariance();
  if (Unconfirmed()) {
    const Vec2 m = Mean();
    // E[(p - m)(p - m)^T] over the inside: E[p p^T] - m E[p]^T - E[p] m^T + m m^T.
    Mat2 spread = inside_second_ - m * inside_mean_.transpose() - inside_mean_ * m.transpose() +
                  m * m.transpose();
    spread = 0.5 * (spread + spread.transpose());
    c += spread;
  }
  return c;
}

Vec2 MapParticleFilter::Mean() const {
  Vec2 m = Vec2::Zero();
  double sum = 0;
  for (const auto& q : particles_) m += q.weight * q.position_n, sum += q.weight;
  return sum > 0 ? Vec2(m / sum) : m;
}

double MapParticleFilter::TriggerVariance() const {
  if (!(options_.wall_follow && options_.free_walk_share > 0)) return Covariance().trace();
  Vec2 m = Vec2::Zero();
  double sum = 0;
  for (const auto& q : particles_)
    if (q.hand != 2) m += q.weight * q.position_n, sum += q.weight;
  if (!(sum > 0)) return Covariance().trace();
  m /= sum;
  double v = 0;
  for (const auto& q : particles_)
    if (q.hand != 2) v += q.weight * (q.position_n - m).squaredNorm();
  return v / sum + 2e-6;
}

Mat2 MapParticleFilter::Covariance() const {
  const Vec2 m = Mean();
  Mat2 c = Mat2::Zero();
  double sum = 0;
  for (const auto& q : particles_) {
    const Vec2 d = q.position_n - m;
    c += q.weight * d * d.transpose();
    sum += q.weight;
  }
  c = sum > 0 ? Mat2(c / sum) : c;
  return 0.5 * (c + c.transpose()) + Mat2::Identity() * 1e-6;
}

double MapParticleFilter::MeanHeadingOffset() const {
  double s = 0, c = 0;
  for (const auto& q : particles_)
    s += q.weight * std::sin(q.heading_offset_rad), c += q.weight * std::cos(q.heading_offset_rad);
  return std::atan2(s, c);
}

}  // namespace trailmark::mapmatch
