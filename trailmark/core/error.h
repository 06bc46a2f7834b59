// SPDX-License-Identifier: MIT
#pragma once
/// Errors in user input carry the file, the line (0 when not applicable) and the problem, and
/// print as "file:line: problem" like a compiler diagnostic.

#include <cstddef>
#include <stdexcept>
#include <string>

namespace trailmark {

class InputError : public std::runtime_error {
 public:
  InputError(std::string file, std::size_t line, std::string problem)
      : std::runtime_error(Format(file, line, problem)),
        file_(std::move(file)),
        line_(line),
        problem_(std::move(problem)) {}

  const std::string& file() const { return file_; }
  std::size_t line() const { return line_; }
  const std::string& problem() const { return problem_; }

 private:
  static std::string Format(const std::string& file, std::size_t line, const std::string& p) {
    return line > 0 ? file + ":" + std::to_string(line) + ": " + p : file + ": " + p;
  }
  std::string file_;
  std::size_t line_;
  std::string problem_;
};

}  // namespace trailmark
