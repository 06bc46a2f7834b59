// SPDX-License-Identifier: MIT
#include "trailmark/core/types.h"

#include <cmath>
#include <numbers>

namespace trailmark {

std::string_view ToString(NodeKind kind) {
  switch (kind) {
    case NodeKind::kAgent:
      return "agent";
    case NodeKind::kCrumb:
      return "crumb";
    case NodeKind::kLandmark:
      return "landmark";
    case NodeKind::kBase:
      return "base";
  }
  return "unknown";
}

std::optional<NodeKind> ParseNodeKind(std::string_view text) {
  if (text == "agent") return NodeKind::kAgent;
  if (text == "crumb") return NodeKind::kCrumb;
  if (text == "landmark") return NodeKind::kLandmark;
  if (text == "base") return NodeKind::kBase;
  return std::nullopt;
}

bool IsValidNodeId(std::string_view id) {
  if (id.empty()) return false;
  for (char c : id) {
    const bool ok = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
                    c == '_' || c == '.' || c == '-';
    if (!ok) return false;
  }
  return true;
}

double WrapAngle(double angle_rad) {
  constexpr double kTwoPi = 2.0 * std::numbers::pi;
  double a = std::fmod(angle_rad + std::numbers::pi, kTwoPi);
  if (a <= 0.0) a += kTwoPi;
  return a - std::numbers::pi;
}

}  // namespace trailmark
