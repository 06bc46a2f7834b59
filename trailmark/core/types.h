// SPDX-License-Identifier: MIT
#pragma once
/// Basic value types shared by every layer of trailmark. No I/O here.

#include <Eigen/Core>
#include <optional>
#include <string>
#include <string_view>

namespace trailmark {

using Vec2 = Eigen::Vector2d;
using Vec3 = Eigen::Vector3d;
using Mat2 = Eigen::Matrix2d;
using Mat3 = Eigen::Matrix3d;

/// Time on the mission clock, in seconds (may be negative).
using TimeS = double;

/// The kinds of node of the mission format (spec: "Kinds").
enum class NodeKind { kAgent, kCrumb, kLandmark, kBase };

std::string_view ToString(NodeKind kind);
/// Parses "agent", "crumb", "landmark", "base"; empty optional otherwise.
std::optional<NodeKind> ParseNodeKind(std::string_view text);

/// Node ids are non-empty strings of [A-Za-z0-9_.-] (spec: "Node ids").
bool IsValidNodeId(std::string_view id);

/// Wraps an angle to (-pi, pi].
double WrapAngle(double angle_rad);

}  // namespace trailmark
