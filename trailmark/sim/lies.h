// SPDX-License-Identifier: MIT
#pragma once
/// The kinds of lie the integrity mechanism must catch (issue 21, item 3), applied to a
/// mission: a surveyed node that is elsewhere than mission.json says, a constant RSSI offset of
/// one node, a scale error of one ranging method (a wrong speed of sound), a link whose readings
/// freeze. Used by the integrity tests and `trailmark reproduce integrity`. No I/O.

#include <string>

#include "trailmark/core/mission.h"

namespace trailmark {

enum class LieKind {
  kMovedNode,   ///< mission.json puts `node` `magnitude` m away from where it is (at 40 deg)
  kRssiOffset,  ///< every RSSI reading of `node` (sent or received) is `magnitude` dB high
  kRangeScale,  ///< every range of kind `node` ("" : all ranges) is x `magnitude`
  kFrozenLink,  ///< from `from_s` on, `node`'s RSSI readings repeat the first one of then
};

struct Lie {
  LieKind kind = LieKind::kMovedNode;
  std::string node;
  double magnitude = 0;
  TimeS from_s = 0;
};

/// "lm3 surveyed 6 m off", "lm2 RSSI +10 dB", ...
std::string Describe(const Lie& lie);
/// Applies the lie to the mission's declarations or streams (the truth is left as it is).
/// Throws std::invalid_argument for a moved node the mission does not declare with a position,
/// or an RSSI lie on a node that has no packets.
void ApplyLie(MissionData& mission, const Lie& lie);
/// Declares every node of `kind` surveyed at its true position (its first truth row) with
/// `sigma_m`; nodes without truth are left as they are.
void SurveyAtTruth(MissionData& mission, NodeKind kind, double sigma_m);

}  // namespace trailmark
