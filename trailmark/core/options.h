// SPDX-License-Identifier: MIT
#pragma once
/// Typed options from `key=value` text, described once. Every estimator has an `Options` struct
/// whose member initializers are its defaults (the paper's, or ours with the reason); next to it
/// an `OptionTable` names each setting for the command line and the registry: key, unit, range
/// and a description. Defaults are read from the struct, never written a second time, so
/// `trailmark pipelines --json`, the docs' option tables and the parser cannot disagree.
///
///   OptionTable<InsOptions> t;
///   t.Real("zupt_sigma", &InsOptions::zupt_sigma_mps, "m/s", OptionBounds::Positive(),
///          "ZUPT pseudo-measurement sigma");
///   InsOptions o;
///   std::string why;
///   if (!t.Apply({{"zupt_sigma", "0.02"}}, &o, &why)) ...  // why names the key and the problem
///
/// No I/O.

#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace trailmark {

/// `--option key=value` pairs as given.
using OptionValues = std::map<std::string, std::string>;

enum class OptionType { kReal, kInteger, kBool, kChoice };
const char* ToString(OptionType type);

/// The values a number may take: [min, max], each end open or closed.
struct OptionBounds {
  double min = -std::numeric_limits<double>::infinity();
  double max = std::numeric_limits<double>::infinity();
  bool min_open = false, max_open = false;

  static OptionBounds Any() { return {}; }
  static OptionBounds Positive() { return {0.0, std::numeric_limits<double>::infinity(), true}; }
  static OptionBounds NonNegative() { return {0.0}; }
  static OptionBounds AtLeast(double v) { return {v}; }
  static OptionBounds Between(double lo, double hi) { return {lo, hi}; }
  /// (lo, hi): both ends excluded.
  static OptionBounds Inside(double lo, double hi) { return {lo, hi, true, true}; }
  bool Contains(double v) const;
  /// "> 0", ">= 0", "1 .. 100000", "" for Any().
  std::string Describe() const;
};

/// One setting as the registry and the docs show it.
struct OptionInfo {
  std::string key;
  OptionType type = OptionType::kReal;
  std::string default_value;  ///< as text, in the form the parser accepts ("auto" when unset)
  std::string unit;           ///< SI unit or "" for dimensionless, counts and choices
  OptionBounds bounds;        ///< numbers only
  std::vector<std::string> choices;  ///< kChoice only
  std::string description;
};

namespace detail {
/// Strict parsers shared by every table: the whole text, finite numbers only.
std::optional<double> ParseReal(const std::string& text);
std::optional<bool> ParseBool(const std::string& text);
std::string FormatReal(double v);
template <class X>
struct IsOptional : std::false_type {
  using type = X;
};
template <class X>
struct IsOptional<std::optional<X>> : std::true_type {
  using type = X;
};
}  // namespace detail

template <class T>
class OptionTable {
 public:
  /// A real number (a double field, or std::optional<double> whose unset state means
  /// `unset_meaning`, e.g. "auto: the detector's default").
  template <class Field>
  OptionTable& Real(std::string key, Field field, std::string unit, OptionBounds bounds,
                    std::string description, std::string unset_meaning = "auto") {
    const std::string k = key;
    return Number(
        {std::move(key), OptionType::kReal, "", std::move(unit), bounds, {}, std::move(description)},
        field, std::move(unset_meaning), [](double v) { return detail::FormatReal(v); },
        [bounds, k](const std::string& text, std::string* why) -> std::optional<double> {
          const auto v = detail::ParseReal(text);
          if (v && bounds.Contains(*v)) return v;
          Fail(why, "option " + k + "='" + text + "' " +
                        (v ? "must be " + bounds.Describe() : "is not a finite number"));
          return std::nullopt;
        });
  }

  /// A whole number (an integral field, or std::optional of one). Fractions and values out of
  /// the bounds are refused with the option's name, never truncated or clamped.
  template <class Field>
  OptionTable& Integer(std::string key, Field field, OptionBounds bounds, std::string description,
                       std::string unset_meaning = "auto") {
    using I = typename detail::IsOptional<FieldType<Field>>::type;
    // Whole numbers up to 2^53 are exact in the double the text is parsed into.
    bounds.min = std::max(bounds.min, static_cast<double>(std::numeric_limits<I>::lowest()));
    bounds.max = std::min(bounds.max, std::min(9007199254740992.0,
                                               static_cast<double>(std::numeric_limits<I>::max())));
    const std::string k = key;
    return Number(
        {std::move(key), OptionType::kInteger, "", "", bounds, {}, std::move(description)}, field,
        std::move(unset_meaning), [](I v) { return std::to_string(v); },
        [bounds, k](const std::string& text, std::string* why) -> std::optional<I> {
          const auto v = detail::ParseReal(text);
          if (!v || *v != std::floor(*v) || !bounds.Contains(*v)) {
            Fail(why, "option " + k + "='" + text + "' must be a whole number " +
                          bounds.Describe());
            return std::nullopt;
          }
          return static_cast<I>(*v);
        });
  }

  /// A yes/no setting: 1/0, true/false, on/off, yes/no.
  template <class Field>
  OptionTable& Flag(std::string key, Field field, std::string description) {
    OptionInfo info{std::move(key), OptionType::kBool, "", "", {}, {}, std::move(description)};
    Entry e;
    e.info = info;
    e.get = [field](const T& t) -> std::string {
      return std::invoke(field, const_cast<T&>(t)) ? "true" : "false";
    };
    e.set = [field, key = info.key](const std::string& text, T& t, std::string* why) -> bool {
      const auto v = detail::ParseBool(text);
      if (!v)
        return Fail(why, "option " + key + "='" + text +
                             "' is not a boolean (1/0, true/false, on/off, yes/no)");
      std::invoke(field, t) = *v;
      return true;
    };
    entries_.push_back(std::move(e));
    return *this;
  }

  /// One of named values (an enum field): `names` maps each accepted word to its value.
  template <class Field, class E>
  OptionTable& Choice(std::string key, Field field, std::vector<std::pair<std::string, E>> names,
                      std::string description) {
    OptionInfo info{std::move(key), OptionType::kChoice, "", "", {}, {}, std::move(description)};
    for (const auto& [name, value] : names) info.choices.push_back(name);
    Entry e;
    e.info = info;
    e.get = [field, names](const T& t) -> std::string {
      const auto& v = std::invoke(field, const_cast<T&>(t));
      for (const auto& [name, value] : names) {
        if (value == v) return name;
      }
      return "?";
    };
    e.set = [field, names, key = info.key](const std::string& text, T& t,
                                           std::string* why) -> bool {
      std::string list;
      for (const auto& [name, value] : names) {
        if (name == text) {
          std::invoke(field, t) = value;
          return true;
        }
        list += (list.empty() ? "" : ", ") + name;
      }
      return Fail(why, "option " + key + "='" + text + "' must be one of " + list);
    };
    entries_.push_back(std::move(e));
    return *this;
  }

  /// Every entry of `table` (options of a part U of T), each key with `prefix` in front.
  template <class U, class Field>
  OptionTable& Include(const std::string& prefix, Field part, const OptionTable<U>& table) {
    for (const auto& sub : table.entries_) {
      Entry e;
      e.info = sub.info;
      e.info.key = prefix + sub.info.key;
      e.get = [part, get = sub.get](const T& t) {
        return get(std::invoke(part, const_cast<T&>(t)));
      };
      e.set = [part, set = sub.set, after = sub.after, prefix](const std::string& text, T& t,
                                                               std::string* why) {
        U& u = std::invoke(part, t);
        if (!set(text, u, why)) {
          if (why && !prefix.empty()) {
            // "option window=..." -> "option ins.window=..."
            const std::string head = "option ";
            if (why->rfind(head, 0) == 0) why->insert(head.size(), prefix);
          }
          return false;
        }
        if (after) after(u);
        return true;
      };
      entries_.push_back(std::move(e));
    }
    return *this;
  }

  /// What else setting the last entry does (e.g. an explicit window in samples clears the
  /// window in seconds).
  OptionTable& AlsoSets(std::function<void(T&)> after) {
    entries_.back().after = std::move(after);
    return *this;
  }

  /// Every setting with its default as `defaults` holds it.
  std::vector<OptionInfo> Describe(const T& defaults = T{}) const {
    std::vector<OptionInfo> out;
    for (const auto& e : entries_) {
      OptionInfo info = e.info;
      info.default_value = e.get(defaults);
      out.push_back(std::move(info));
    }
    return out;
  }

  /// The keys, in table order.
  std::vector<std::string> Keys() const {
    std::vector<std::string> out;
    for (const auto& e : entries_) out.push_back(e.info.key);
    return out;
  }

  /// Applies `values` to `options`. An unknown key, a malformed value or one out of range:
  /// false, with `why` naming the key (and, for an unknown one, the valid keys); `options` may
  /// then be partly changed.
  bool Apply(const OptionValues& values, T* options, std::string* why) const {
    for (const auto& [key, text] : values) {
      const Entry* entry = nullptr;
      for (const auto& e : entries_) {
        if (e.info.key == key) entry = &e;
      }
      if (entry == nullptr) {
        std::string list;
        for (const auto& e : entries_) list += (list.empty() ? "" : ", ") + e.info.key;
        return Fail(why, "unknown option '" + key + "' " +
                             (list.empty() ? std::string("(it takes none)")
                                           : "(known: " + list + ")"));
      }
      if (!entry->set(text, *options, why)) return false;
      if (entry->after) entry->after(*options);
    }
    return true;
  }

 private:
  template <class>
  friend class OptionTable;
  template <class Field>
  using FieldType = std::remove_reference_t<decltype(std::invoke(std::declval<Field>(),
                                                                 std::declval<T&>()))>;
  /// A number entry: `format` writes a value, `parse` checks text (nullopt and `why` when bad).
  template <class Field, class Format, class Parse>
  OptionTable& Number(OptionInfo info, Field field, std::string unset_meaning, Format format,
                      Parse parse) {
    using V = FieldType<Field>;
    Entry e;
    e.info = std::move(info);
    e.get = [field, unset_meaning, format](const T& t) -> std::string {
      const auto& v = std::invoke(field, const_cast<T&>(t));
      if constexpr (detail::IsOptional<V>::value) {
        return v ? format(*v) : unset_meaning;
      } else {
        return format(v);
      }
    };
    e.set = [field, parse](const std::string& text, T& t, std::string* why) -> bool {
      const auto v = parse(text, why);
      if (!v) return false;
      std::invoke(field, t) = *v;
      return true;
    };
    entries_.push_back(std::move(e));
    return *this;
  }
  struct Entry {
    OptionInfo info;
    std::function<std::string(const T&)> get;
    std::function<bool(const std::string&, T&, std::string*)> set;
    std::function<void(T&)> after;
  };
  static bool Fail(std::string* why, std::string message) {
    if (why) *why = std::move(message);
    return false;
  }
  std::vector<Entry> entries_;
};

}  // namespace trailmark
