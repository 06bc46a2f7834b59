// SPDX-License-Identifier: MIT
#pragma once
/// Internal to io/: reading JSON input files with errors that name the file, the line (parse
/// errors) or the JSON pointer of the offending value. Not part of the public headers' API
/// (it exposes nlohmann::json).

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

namespace trailmark::io_detail {

/// The whole file; InputError when missing, unreadable or above 64 MiB.
std::string ReadText(const std::filesystem::path& path);
/// InputError with the line of a syntax error.
nlohmann::json ParseJson(const std::string& text, const std::string& source);
/// InputError "source: where: problem".
[[noreturn]] void Bad(const std::string& source, const std::string& where,
                      const std::string& problem);
/// A finite number, else InputError naming `where`.
double Number(const nlohmann::json& j, const std::string& source, const std::string& where);

}  // namespace trailmark::io_detail
