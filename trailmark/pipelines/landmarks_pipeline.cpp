#include "trailmark/pipelines/landmarks_pipeline.h"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <algorithm>
#include <map>
#include <optional>
#include <set>

#include "trailmark/core/error.h"
#include "trailmark/landmarks/landmark_ukf.h"
#include "trailmark/landmarks/stop_and_go.h"
#include "trailmark/pipelines/merged_stream.h"
#include "trailmark/pipelines/pipeline_options.h"
#include "trailmark/pipelines/step_source.h"
#include "trailmark/radio/path_loss.h"

namespace trailmark {

bool LandmarksPipeline::CanRun(const MissionDirectory& mission) const {
  int declared = 0;
  for (const NodeInfo& n : mission.info().nodes) declared += n.kind == NodeKind::kLandmark;
  return HasSteps(mission) && mission.Has("rssi.csv") && declared >= 3;
}

namespace {

struct AgentState {
  Vec2 position = Vec2::Zero();
  Mat2 cov = Mat2::Identity();
  bool stopped = false;
  std::vector<double> sum;
  std::vector<int> count;
  std::optional<landmarks::LandmarkUkf> ukf;
};

struct Stop {
  Vec2 standing = Vec2::Zero();
  std::vector<std::optional<double>> rssi;  ///< averaged per landmark
};

}  // namespace

PipelineSummary LandmarksPipeline::Run(const PipelineContext& context, EstimateSink& sink) const {
  const MissionDirectory& mission = context.mission;
  const auto [ins_options, rest] = SplitInsOptions(context.options);
  PipelineOptions po(rest, name());
  const double drift_per_m = po.Double("drift_per_m", 0.05);
  const double rssi_sigma_db = po.Double("rssi_sigma_db", 6.0);
  const std::string loss = po.String("loss", "huber");
  po.RejectUnknown();
  if (!(drift_per_m > 0) || !(rssi_sigma_db > 0)) {
    throw std::invalid_argument("pipeline " + name() + ": drift_per_m and rssi_sigma_db must be > 0");
  }
  landmarks::StopAndGoOptions sgo;
  if (loss == "squared") sgo.loss = landmarks::Loss::kSquared;
  else if (loss == "huber") sgo.loss = landmarks::Loss::kHuber;
  else if (loss == "cauchy") sgo.loss = landmarks::Loss::kCauchy;
  else throw std::invalid_argument("pipeline " + name() + ": loss must be squared, huber or cauchy");

  PipelineSummary summary;
  mission.Require("rssi.csv", "the " + name() + " pipeline");
  const auto ins_steps = InsStepsUnlessStepFile(mission, ins_options, "the " + name() + " pipeline", &summary);
  radio::LogDistanceModel model;
  const bool calibrated = mission.info().radio.has_value();
  if (calibrated) {
    model = radio::LogDistanceModel::From(*mission.info().radio);
  } else {
    summary.notes.push_back(
        "mission.json has no radio calibration: fitted online from the stops' RSSI of surveyed "
        "landmarks (default log-distance model until then)");
  }
  std::vector<radio::CalibrationPair> calibration;  // (distance stop-surveyed landmark, rssi)
  int refits = 0;

  // Landmarks: known (position, sigma) or to be estimated.
  std::vector<std::string> ids;
  std::map<std::string, int> index;
  std::vector<bool> known;
  std::vector<std::optional<Vec2>> estimate;
  std::vector<Mat2> estimate_cov;
  for (const NodeInfo& n : mission.info().nodes) {
    if (n.kind != NodeKind::kLandmark) continue;
    index[n.id] = static_cast<int>(ids.size());
    ids.push_back(n.id);
    known.push_back(n.position.has_value());
    estimate.push_back(n.position ? std::optional<Vec2>(n.position->head<2>()) : std::nullopt);
    const double s = n.position_sigma_m.value_or(0.01);
    estimate_cov.push_back(Mat2::Identity() * s * s);
  }
  if (ids.size() < 3) {
    throw InputError(mission.Path("mission.json").string(), 0,
                     "the " + name() + " pipeline needs at least 3 landmarks in mission.json");
  }
  const int B = static_cast<int>(ids.size());

  std::map<std::string, AgentState> agents;
  for (const NodeInfo& n : mission.info().nodes) {
    if (n.kind != NodeKind::kAgent) continue;
    AgentState a;
    const auto start = mission.info().AgentStart(n);
    a.position = start ? Vec2(start->head<2>()) : Vec2::Zero();
    const double s = start ? n.start_sigma_m.value_or(0.05) : 100.0;
    a.cov = Mat2::Identity() * s * s;
    if (!start) summary.notes.push_back("agent '" + n.id + "' has no start: 100 m prior");
    a.sum.assign(B, 0.0);
    a.count.assign(B, 0);
    if (ukf_) {
      landmarks::LandmarkUkfOptions uo;
      uo.initial_sigma_m = s;
      uo.rssi_sigma_db = rssi_sigma_db;
      a.ukf.emplace(a.position, model, uo);
    }
    agents[n.id] = std::move(a);
  }

  std::vector<Stop> stops;
  std::set<std::string> notes;
  std::size_t fixes = 0, ukf_updates = 0;
  auto emit_agent = [&](TimeS t, const std::string& id, const AgentState& a) {
    const Vec2 p = a.ukf ? a.ukf->position() : a.position;
    const Mat2 c = a.ukf ? a.ukf->position_cov() : a.cov;
    sink.Add({t, id, Vec3(p.x(), p.y(), 0), c(0, 0), c(0, 1), c(1, 1)});
  };
  auto emit_landmarks = [&](TimeS t) {
    for (int j = 0; j < B; ++j) {
      if (!estimate[j]) continue;
      const Mat2& c = estimate_cov[j];
      sink.Add({t, ids[j], Vec3(estimate[j]->x(), estimate[j]->y(), 0), c(0, 0), c(0, 1), c(1, 1)});
    }
  };
  auto ranges_of = [&](const Stop& s, std::vector<std::optional<double>>* r, std::vector<double>* sg) {
    for (int j = 0; j < B; ++j) {
      if (s.rssi[j]) {
        const auto range = radio::ToRange(model, *s.rssi[j]);
        r->push_back(range.range_m);
        sg->push_back(std::max(range.sigma_m, 0.1));
      } else {
        r->push_back(std::nullopt);
        sg->push_back(1.0);
      }
    }
  };

  MergedStream stream(mission, {.events = true, .steps = true, .ranges = false, .bearings = false,
                                .rssi = true, .steps_override = ins_steps ? &*ins_steps : nullptr});
  MissionRow row;
  TimeS t_last = 0;
  bool first = true;
  while (stream.Next(row)) {
    const TimeS t = RowTime(row);
    if (first) {
      emit_landmarks(t);
      first = false;
    }
    t_last = std::max(t_last, t);
    if (const auto* step = std::get_if<Step>(&row)) {
      auto it = agents.find(step->agent);
      if (it == agents.end()) {
        throw InputError(mission.dir().string(), 0, "'" + step->agent + "' has steps but is not an agent");
      }
      AgentState& a = it->second;
      const Vec2 d = step->delta_n.head<2>();
      const double s = drift_per_m * d.norm();
      a.position += d;
      a.cov += Mat2::Identity() * (s * s + 1e-8);
      if (a.ukf) a.ukf->PredictWithDisplacement(d, Mat2::Identity() * (s * s + 1e-8));
      emit_agent(step->t1, step->agent, a);
    } else if (const auto* p = std::get_if<RssiPacket>(&row)) {
      const bool rx_agent = agents.count(p->rx) != 0;
      const std::string& agent = rx_agent ? p->rx : p->tx;
      const std::string& other = rx_agent ? p->tx : p->rx;
      auto ait = agents.find(agent);
      auto lit = index.find(other);
      if (ait == agents.end() || lit == index.end()) continue;
      AgentState& a = ait->second;
      const int j = lit->second;
      if (a.stopped) {
        a.sum[j] += p->rssi_dbm;
        ++a.count[j];
      }
      if (a.ukf && estimate[j] && a.ukf->UpdateRssi(*estimate[j], estimate_cov[j], p->rssi_dbm)) {
        ++ukf_updates;
      }
    } else if (const auto* e = std::get_if<MissionEvent>(&row)) {
      auto ait = agents.find(e->agent);
      if (ait == agents.end()) continue;
      AgentState& a = ait->second;
      if (e->event == "stop") {
        a.stopped = true;
        std::fill(a.sum.begin(), a.sum.end(), 0.0);
        std::fill(a.count.begin(), a.count.end(), 0);
        if (a.ukf) a.ukf->ZeroMotion();
      } else if (e->event == "go" && a.stopped) {
        a.stopped = false;
        Stop s;
        s.standing = a.position;
        for (int j = 0; j < B; ++j) {
          s.rssi.push_back(a.count[j] ? std::optional<double>(a.sum[j] / a.count[j]) : std::nullopt);
        }
        stops.push_back(s);
        // Online calibration (no calibration in mission.json): every stop's averaged RSSI of a
        // surveyed landmark at the PDR distance is a pair; refit once the distances spread.
        if (!calibrated) {
          for (int j = 0; j < B; ++j) {
            if (known[j] && s.rssi[j]) {
              calibration.push_back({std::max((s.standing - *estimate[j]).norm(), 0.3), *s.rssi[j]});
            }
          }
          double dmin = 1e300, dmax = 0;
          for (const auto& c : calibration) dmin = std::min(dmin, c.distance_m), dmax = std::max(dmax, c.distance_m);
          if (calibration.size() >= 4 && dmax > 2 * dmin) {
            try {
              const radio::PathLossFit fit = radio::FitLogDistance(calibration, 0.0, 0.5);
              if (fit.model.path_loss_exponent > 1.0 && fit.model.path_loss_exponent < 10.0) {
                model = fit.model;
                model.sigma_db = std::max(fit.residual_sigma_db, 1.0);
                ++refits;
                for (auto& [id, ag] : agents) {
                  if (ag.ukf) ag.ukf->SetRadioModel(model);
                }
              }
            } catch (const std::invalid_argument&) {
            }
          }
        }
        // Landmarks from every stop so far (standing positions from the PDR, sec. 6.2).
        landmarks::StopAndGoProblem prob;
        for (int j = 0; j < B; ++j) {
          prob.landmarks.push_back(known[j] ? *estimate[j] : Vec2::Zero());
          prob.landmark_known.push_back(known[j]);
        }
        for (const auto& st : stops) {
          prob.standing.push_back(st.standing);
          prob.standing_known.push_back(true);
          std::vector<std::optional<double>> r;
          std::vector<double> sg;
          ranges_of(st, &r, &sg);
          prob.range_m.push_back(r);
          prob.sigma_m.push_back(sg);
        }
        const landmarks::StopAndGoResult res = landmarks::SolveStopAndGo(prob, sgo);
        notes.clear();  // the latest solve's geometry report
        for (const auto& n : res.notes) notes.insert(n);
        for (int j = 0; j < B; ++j) {
          if (known[j]) continue;
          int heard = 0;
          for (const auto& st : stops) heard += st.rssi[j].has_value();
          if (heard >= 3) {
            estimate[j] = res.landmarks[j];
            estimate_cov[j] = res.landmark_cov[j] + Mat2::Identity() * 1e-4;
          }
        }
        emit_landmarks(e->t);
        // Re-localize the handheld at this stop with the landmarks (sec. 6.2).
        landmarks::StopAndGoProblem fix;
        std::vector<std::optional<double>> r;
        std::vector<double> sg;
        ranges_of(s, &r, &sg);
        int usable = 0;
        for (int j = 0; j < B; ++j) {
          fix.landmarks.push_back(estimate[j].value_or(Vec2::Zero()));
          fix.landmark_known.push_back(true);
          if (!estimate[j]) r[j].reset();
          usable += r[j].has_value();
        }
        if (usable >= 3 && !a.ukf) {
          fix.standing = {a.position};
          fix.standing_known = {false};
          fix.range_m = {r};
          fix.sigma_m = {sg};
          const landmarks::StopAndGoResult fr = landmarks::SolveStopAndGo(fix, sgo);
          const Mat2 c_fix = fr.standing_cov[0] + Mat2::Identity() * 1e-4;
          // Combine the fix with dead reckoning (information-weighted).
          const Mat2 K = a.cov * (a.cov + c_fix).inverse();
          a.position += K * (fr.standing[0] - a.position);
          a.cov = (Mat2::Identity() - K) * a.cov;
          a.cov = 0.5 * (a.cov + a.cov.transpose());
          ++fixes;
          emit_agent(e->t, e->agent, a);
        }
      }
    }
  }
  emit_landmarks(t_last);
  for (const auto& n : notes) summary.notes.push_back(n);
  int localized = 0;
  for (int j = 0; j < B; ++j) localized += !known[j] && estimate[j].has_value();
  summary.numbers["stops"] = static_cast<double>(stops.size());
  summary.numbers["landmarks_localized"] = localized;
  summary.numbers["landmarks_known"] = static_cast<double>(std::count(known.begin(), known.end(), true));
  summary.numbers["handheld_fixes"] = static_cast<double>(fixes);
  summary.numbers["ukf_rssi_updates"] = static_cast<double>(ukf_updates);
  summary.numbers["radio_refits"] = refits;
  summary.numbers["radio_path_loss_exponent"] = model.path_loss_exponent;
  summary.numbers["radio_alpha_dbm"] = model.alpha_dbm;
  context.progress(1.0);
  return summary;
}

}  // namespace trailmark
