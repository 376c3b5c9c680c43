#include "proto/json_schema.h"

#include <algorithm>
#include <cmath>
#include <regex>
#include <vector>

#include "proto/did_you_mean.h"
#include "proto/json_pointer.h"

namespace tessera::proto {

using nlohmann::json;

namespace {

// Guards against reference cycles in a (trusted, but possibly wrong) schema.
constexpr int kMaxSchemaDepth = 200;

std::string child(const std::string& pointer, const std::string& key) {
  return pointer + "/" + json_pointer_token(key);
}
std::string child(const std::string& pointer, size_t index) {
  return pointer + "/" + std::to_string(index);
}

size_t pointer_depth(const std::string& pointer) {
  size_t n = 0;
  for (char c : pointer) n += c == '/';
  return n;
}

// JSON Schema counts string length in code points, not bytes.
size_t code_points(const std::string& s) {
  size_t n = 0;
  for (unsigned char c : s) n += (c & 0xC0) != 0x80;
  return n;
}

bool is_integer(const json& v) {
  if (v.is_number_integer()) return true;
  if (!v.is_number_float()) return false;
  double d = v.get<double>();
  return std::isfinite(d) && d == std::floor(d);
}

bool has_type(const json& v, const std::string& type) {
  if (type == "object") return v.is_object();
  if (type == "array") return v.is_array();
  if (type == "string") return v.is_string();
  if (type == "boolean") return v.is_boolean();
  if (type == "null") return v.is_null();
  if (type == "number") return v.is_number();
  if (type == "integer") return is_integer(v);
  return false;
}

std::string article_type(const std::string& type) {
  if (type == "object") return "an object";
  if (type == "array") return "an array";
  if (type == "string") return "a string";
  if (type == "boolean") return "true or false";
  if (type == "null") return "null";
  if (type == "number") return "a number";
  if (type == "integer") return "an integer";
  return type;
}

// A bound as the schema wrote it, an integer without a decimal point ("at least 1", not "at least 1.0").
std::string number_text(const json& bound) {
  if (bound.is_number_float()) {
    const double d = bound.get<double>();
    if (std::isfinite(d) && d == std::floor(d) && std::fabs(d) < 9007199254740992.0)  // 2^53: exact as an integer
      return std::to_string(static_cast<long long>(d));
  }
  return bound.dump();
}

using Errors = std::vector<SchemaError>;

Errors fail(const std::string& at, std::string message, const char* keyword) {
  return Errors{SchemaError{at, std::move(message), keyword}};
}

// Checks an instance against a schema. The errors come in document order: only the first (`max_errors` 1), or up to
// `max_errors` of them, in which case the members of an object and the items of an array are all checked (an error
// in one does not hide those of the others) and a failed alternative of anyOf/oneOf reports the errors of the branch
// that got furthest.
class Validator {
 public:
  Validator(const SchemaSet& set, int max_depth, size_t max_errors)
      : set_(set), max_depth_(max_depth), max_errors_(std::max<size_t>(1, max_errors)) {}

  Errors check(const json& schema, const std::string& doc, const json& v, const std::string& at, int schema_depth) {
    if (schema_depth > kMaxSchemaDepth) return fail(at, "schema nesting too deep (a $ref cycle?)", "$ref");
    if (pointer_depth(at) > static_cast<size_t>(max_depth_))
      return fail(at, "nested too deeply (limit " + std::to_string(max_depth_) + ")", "depth");
    if (schema.is_boolean()) {
      if (schema.get<bool>()) return {};
      return fail(at, "is not allowed here", "false");
    }
    if (!schema.is_object()) return {};

    if (auto it = schema.find("$ref"); it != schema.end() && it->is_string()) {
      std::string target_doc;
      const json* target = set_.resolve(doc, it->get<std::string>(), &target_doc);
      if (!target) return fail(at, "schema error: cannot resolve " + it->get<std::string>(), "$ref");
      if (Errors e = check(*target, target_doc, v, at, schema_depth + 1); !e.empty()) return e;
    }
    if (auto e = check_type(schema, v, at)) return {*e};
    if (auto it = schema.find("const"); it != schema.end() && v != *it)
      return fail(at, "must be " + it->dump(), "const");
    if (auto it = schema.find("enum"); it != schema.end() && it->is_array()) {
      bool found = false;
      std::vector<std::string> names;
      for (const json& option : *it) {
        found = found || option == v;
        if (option.is_string()) names.push_back(option.get<std::string>());
      }
      if (!found)
        return fail(
            at, "must be one of " + enum_text(*it) + (v.is_string() ? did_you_mean(v.get<std::string>(), names) : ""),
            "enum");
    }
    if (v.is_number()) {
      if (auto e = check_number(schema, v, at)) return {*e};
    }
    if (v.is_string()) {
      if (auto e = check_string(schema, v.get<std::string>(), at)) return {*e};
    }
    if (v.is_object()) {
      if (Errors e = check_object(schema, doc, v, at, schema_depth); !e.empty()) return e;
    }
    if (v.is_array()) {
      if (Errors e = check_array(schema, doc, v, at, schema_depth); !e.empty()) return e;
    }
    return check_combinators(schema, doc, v, at, schema_depth);
  }

 private:
  // Adds `more` to `errors`; true when no more are wanted.
  bool add(Errors* errors, Errors&& more) const {
    for (SchemaError& e : more) {
      if (errors->size() >= max_errors_) break;
      errors->push_back(std::move(e));
    }
    return errors->size() >= max_errors_;
  }

  static std::string enum_text(const json& options) {
    std::string out;
    for (size_t i = 0; i < options.size(); ++i) {
      if (i > 0) out += i + 1 == options.size() ? " or " : ", ";
      out += options[i].dump();
    }
    return out;
  }

  std::optional<SchemaError> check_type(const json& schema, const json& v, const std::string& at) {
    auto it = schema.find("type");
    if (it == schema.end()) return std::nullopt;
    std::vector<std::string> types;
    if (it->is_string())
      types.push_back(it->get<std::string>());
    else if (it->is_array())
      for (const json& t : *it)
        if (t.is_string()) types.push_back(t.get<std::string>());
    std::string expected;
    for (size_t i = 0; i < types.size(); ++i) {
      if (has_type(v, types[i])) return std::nullopt;
      if (i > 0) expected += " or ";
      expected += article_type(types[i]);
    }
    return SchemaError{at, "must be " + expected, "type"};
  }

  // Where `v` lies against `bound`: below (< 0), equal (0) or above (> 0); exactly when both are integers (a double
  // holds every integer only up to 2^53, and 2^53 + 1 read as one equals 2^53), as doubles otherwise.
  static int compare(const json& v, const json& bound) {
    if (v.is_number_integer() && bound.is_number_integer()) {
      auto wide = [](const json& x) -> __int128 {
        return x.is_number_unsigned() ? static_cast<__int128>(x.get<uint64_t>()) : x.get<int64_t>();
      };
      const __int128 a = wide(v), b = wide(bound);
      return a < b ? -1 : a > b ? 1 : 0;
    }
    const double a = v.get<double>(), b = bound.get<double>();
    return a < b ? -1 : a > b ? 1 : a == b ? 0 : 2;  // 2: unordered (NaN), which passes no bound
  }

  std::optional<SchemaError> check_number(const json& schema, const json& v, const std::string& at) {
    auto against = [&](const char* key) -> std::optional<int> {
      auto it = schema.find(key);
      if (it == schema.end() || !it->is_number()) return std::nullopt;
      return compare(v, *it);
    };
    auto text = [&](const char* key) { return number_text(schema.at(key)); };
    if (auto c = against("minimum"); c && !(*c >= 0 && *c != 2))
      return SchemaError{at, "must be at least " + text("minimum"), "minimum"};
    if (auto c = against("maximum"); c && !(*c <= 0))
      return SchemaError{at, "must be at most " + text("maximum"), "maximum"};
    if (auto c = against("exclusiveMinimum"); c && !(*c == 1))
      return SchemaError{at, "must be greater than " + text("exclusiveMinimum"), "exclusiveMinimum"};
    if (auto c = against("exclusiveMaximum"); c && !(*c < 0))
      return SchemaError{at, "must be less than " + text("exclusiveMaximum"), "exclusiveMaximum"};
    return std::nullopt;
  }

  std::optional<SchemaError> check_string(const json& schema, const std::string& s, const std::string& at) {
    const size_t n = code_points(s);
    if (auto it = schema.find("minLength"); it != schema.end() && it->is_number() && n < it->get<double>())
      return SchemaError{at, "must have at least " + number_text(*it) + " characters", "minLength"};
    if (auto it = schema.find("maxLength"); it != schema.end() && it->is_number() && n > it->get<double>())
      return SchemaError{at, "must have at most " + number_text(*it) + " characters", "maxLength"};
    if (auto it = schema.find("pattern"); it != schema.end() && it->is_string()) {
      // ECMAScript syntax, as the JSON Schema specification asks; unanchored like every validator.
      const std::regex re(it->get<std::string>(), std::regex::ECMAScript);
      if (!std::regex_search(s, re)) return SchemaError{at, "must match " + it->get<std::string>(), "pattern"};
    }
    return std::nullopt;
  }

  Errors check_object(const json& schema, const std::string& doc, const json& v, const std::string& at,
                      int schema_depth) {
    Errors errors;
    if (auto it = schema.find("required"); it != schema.end() && it->is_array()) {
      for (const json& key : *it) {
        if (key.is_string() && !v.contains(key.get<std::string>()) &&
            add(&errors,
                fail(child(at, key.get<std::string>()), "\"" + key.get<std::string>() + "\" is required", "required")))
          return errors;
      }
    }
    const json* properties = nullptr;
    if (auto it = schema.find("properties"); it != schema.end() && it->is_object()) properties = &*it;
    const json* additional = nullptr;
    if (auto it = schema.find("additionalProperties"); it != schema.end()) additional = &*it;
    const json* names = nullptr;
    if (auto it = schema.find("propertyNames"); it != schema.end()) names = &*it;
    for (const auto& [key, value] : v.items()) {
      const std::string p = child(at, key);
      if (names) {
        if (Errors e = check(*names, doc, json(key), p, schema_depth + 1); !e.empty()) {
          e.front().message = "property name \"" + key + "\" " + e.front().message;
          e.front().pointer = p;
          e.resize(1);
          if (add(&errors, std::move(e))) return errors;
          continue;
        }
      }
      if (properties) {
        if (auto pit = properties->find(key); pit != properties->end()) {
          if (add(&errors, check(*pit, doc, value, p, schema_depth + 1))) return errors;
          continue;
        }
      }
      if (additional) {
        if (additional->is_boolean() && !additional->get<bool>()) {
          std::vector<std::string> known;
          if (properties)
            for (const auto& [name, unused] : properties->items()) known.push_back(name);
          if (add(&errors,
                  fail(p, "unknown property \"" + key + "\"" + did_you_mean(key, known), "additionalProperties")))
            return errors;
          continue;
        }
        if (add(&errors, check(*additional, doc, value, p, schema_depth + 1))) return errors;
      }
    }
    return errors;
  }

  Errors check_array(const json& schema, const std::string& doc, const json& v, const std::string& at,
                     int schema_depth) {
    if (auto it = schema.find("minItems"); it != schema.end() && it->is_number() && v.size() < it->get<double>())
      return fail(at, "must have at least " + number_text(*it) + " items", "minItems");
    if (auto it = schema.find("maxItems"); it != schema.end() && it->is_number() && v.size() > it->get<double>())
      return fail(at, "must have at most " + number_text(*it) + " items", "maxItems");
    Errors errors;
    if (auto it = schema.find("items"); it != schema.end()) {
      for (size_t i = 0; i < v.size(); ++i)
        if (add(&errors, check(*it, doc, v[i], child(at, i), schema_depth + 1))) return errors;
    }
    return errors;
  }

  // Of the failed alternatives (each with its errors, first first), the errors of the one that says most: the branch
  // whose first error is the deepest in the instance (it got furthest), preferring one whose type matched. When
  // every branch failed on its type at the same place, one message lists what would have been accepted.
  static Errors most_specific(std::vector<Errors>& branches) {
    size_t best = 0;
    bool all_type = true;
    const SchemaError& front = branches.front().front();
    for (size_t i = 0; i < branches.size(); ++i) {
      const SchemaError& e = branches[i].front();
      const SchemaError& b = branches[best].front();
      all_type = all_type && e.keyword == "type" && e.pointer == front.pointer;
      const size_t d = pointer_depth(e.pointer), bd = pointer_depth(b.pointer);
      if (d > bd || (d == bd && b.keyword == "type" && e.keyword != "type")) best = i;
    }
    if (all_type && branches.size() > 1) {
      std::vector<std::string> expected;
      for (const Errors& branch : branches) {
        const std::string& message = branch.front().message;
        std::string m = message.substr(message.rfind("must be ", 0) == 0 ? 8 : 0);
        if (std::find(expected.begin(), expected.end(), m) == expected.end()) expected.push_back(m);
      }
      std::string msg = "must be ";
      for (size_t i = 0; i < expected.size(); ++i) msg += (i > 0 ? " or " : "") + expected[i];
      return fail(front.pointer, msg, "type");
    }
    return std::move(branches[best]);
  }

  Errors check_combinators(const json& schema, const std::string& doc, const json& v, const std::string& at,
                           int schema_depth) {
    Errors errors;
    if (auto it = schema.find("allOf"); it != schema.end() && it->is_array()) {
      for (const json& sub : *it)
        if (add(&errors, check(sub, doc, v, at, schema_depth + 1))) return errors;
      if (!errors.empty()) return errors;
    }
    if (auto it = schema.find("anyOf"); it != schema.end() && it->is_array() && !it->empty()) {
      std::vector<Errors> failed;
      for (const json& sub : *it) {
        Errors e = check(sub, doc, v, at, schema_depth + 1);
        if (e.empty()) {
          failed.clear();
          break;
        }
        failed.push_back(std::move(e));
      }
      if (!failed.empty()) return most_specific(failed);
    }
    if (auto it = schema.find("oneOf"); it != schema.end() && it->is_array() && !it->empty()) {
      std::vector<Errors> failed;
      int passed = 0;
      for (const json& sub : *it) {
        if (Errors e = check(sub, doc, v, at, schema_depth + 1); !e.empty())
          failed.push_back(std::move(e));
        else
          ++passed;
      }
      if (passed == 0) return most_specific(failed);
      if (passed > 1) return fail(at, "matches more than one alternative", "oneOf");
    }
    if (auto it = schema.find("if"); it != schema.end()) {
      const bool matched = check(*it, doc, v, at, schema_depth + 1).empty();
      const char* branch = matched ? "then" : "else";
      if (auto b = schema.find(branch); b != schema.end()) return check(*b, doc, v, at, schema_depth + 1);
    }
    return {};
  }

  const SchemaSet& set_;
  int max_depth_;
  size_t max_errors_;
};

}  // namespace

void SchemaSet::add(const std::string& name, json schema) {
  documents_[name] = std::move(schema);
}

const json* SchemaSet::document(const std::string& name) const {
  auto it = documents_.find(name);
  return it == documents_.end() ? nullptr : &it->second;
}

const json* SchemaSet::resolve(const std::string& base, const std::string& ref, std::string* target_doc) const {
  const size_t hash = ref.find('#');
  std::string location = ref.substr(0, hash);
  const std::string fragment = hash == std::string::npos ? "" : ref.substr(hash + 1);
  // Documents are known by file name; a relative or absolute URI resolves to its last path segment.
  if (size_t slash = location.rfind('/'); slash != std::string::npos) location = location.substr(slash + 1);
  *target_doc = location.empty() ? base : location;
  const json* doc = document(*target_doc);
  if (!doc) return nullptr;
  if (fragment.empty()) return doc;
  if (fragment[0] != '/') return nullptr;  // plain-name anchors are not used by the contract
  try {
    const json::json_pointer ptr(fragment);
    if (!doc->contains(ptr)) return nullptr;
    return &doc->at(ptr);
  } catch (const json::exception&) {
    return nullptr;
  }
}

std::optional<SchemaError> SchemaSet::validate(const json& instance, const std::string& name, int max_depth) const {
  std::vector<SchemaError> errors = validate_all(instance, name, max_depth, 1);
  if (errors.empty()) return std::nullopt;
  return std::move(errors.front());
}

std::vector<SchemaError> SchemaSet::validate_all(const json& instance, const std::string& name, int max_depth,
                                                 size_t max_errors) const {
  const json* schema = document(name);
  if (!schema) return {SchemaError{"", "no schema named " + name, "$ref"}};
  Validator validator(*this, max_depth, max_errors);
  return validator.check(*schema, name, instance, "", 0);
}

size_t json_nesting_depth(std::string_view text) {
  size_t depth = 0, deepest = 0;
  bool in_string = false, escaped = false;
  for (char c : text) {
    if (in_string) {
      if (escaped)
        escaped = false;
      else if (c == '\\')
        escaped = true;
      else if (c == '"')
        in_string = false;
      continue;
    }
    switch (c) {
      case '"':
        in_string = true;
        break;
      case '[':
      case '{':
        deepest = std::max(deepest, ++depth);
        break;
      case ']':
      case '}':
        if (depth > 0) --depth;
        break;
      default:
        break;
    }
  }
  return deepest;
}

std::optional<json> SchemaSet::valid_remainder(const json& instance, const std::string& name,
                                               const std::vector<SchemaError>& errors, int max_depth) const {
  json rest = instance;
  for (const SchemaError& e : errors) {
    if (e.pointer.empty()) return std::nullopt;
    json::json_pointer at;
    try {
      at = json::json_pointer(e.pointer);
    } catch (const json::exception&) {
      return std::nullopt;
    }
    const json::json_pointer parent = at.parent_pointer();
    if (!rest.contains(parent) || !rest[parent].is_object()) return std::nullopt;
    json& holder = rest[parent];
    const auto it = holder.find(at.back());
    if (it == holder.end()) continue;  // left out already, with an error of its own
    if (e.keyword != "additionalProperties" && it->is_structured()) return std::nullopt;
    holder.erase(it);
  }
  if (!validate_all(rest, name, max_depth, 1).empty()) return std::nullopt;
  return rest;
}

}  // namespace tessera::proto
