#pragma once
// What every bound settings struct offers in Python, written once: construction from
// keyword arguments (`AlignParams(voxel_size=0.01, threads=2)`), a repr that shows every
// field, equality, copy and deepcopy. The fields are the struct's bound properties (its
// def_readwrite and def_property), found on the class when called, in the order they were
// bound: a field added to the binding is in the constructor and the repr with no other line.
// A nested group of settings (`define_group`: `params.search`, itself such a struct, listed
// in `_groups`) is a property whose fields are also the outer struct's, under the same
// names: the outer struct's repr and equality are those of its flat fields, and its
// keywords are those fields and the groups (a group given is copied in).

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <algorithm>
#include <string>
#include <vector>

namespace spectral_vs::python {

namespace py = pybind11;

namespace settings_detail {

/// The nested groups of the bound class `type` (its `_groups`, a tuple of names; none if
/// it has none): settable, but not fields of their own (their fields are).
inline std::vector<std::string> group_names(const py::handle& type) {
  std::vector<std::string> names;
  if (py::hasattr(type, "_groups")) {
    for (const auto& name : type.attr("_groups")) names.push_back(py::str(name));
  }
  return names;
}

/// The settable properties of the bound class `type`, in the order they were bound.
inline std::vector<std::string> field_names(const py::handle& type) {
  const py::object property = py::module_::import("builtins").attr("property");
  const std::vector<std::string> groups = group_names(type);
  std::vector<std::string> names;
  for (const auto& item : type.attr("__dict__").attr("items")()) {
    const auto pair = item.cast<py::tuple>();
    const std::string name = pair[0].cast<std::string>();
    if (name.rfind('_', 0) == 0 || !py::isinstance(pair[1], property)) continue;
    if (pair[1].attr("fset").is_none()) continue;  // read-only: not a setting
    if (std::find(groups.begin(), groups.end(), name) != groups.end()) continue;
    names.push_back(name);
  }
  return names;
}

inline std::string type_name(const py::handle& self) {
  return py::str(py::type::of(self).attr("__name__")).cast<std::string>();
}

/// A field's value as Python source: arrays as (nested) lists, the rest as repr shows it.
inline std::string value_repr(const py::handle& value) {
  if (py::isinstance<py::array>(value)) return py::repr(value.attr("tolist")());
  return py::repr(value);
}

/// Sets the keyword arguments on `self` (a bound settings object). TypeError for a name
/// that is no field (with the closest field names) or a value of the wrong type.
inline void set_fields(const py::object& self, const py::kwargs& fields) {
  const std::string name = type_name(self);
  std::vector<std::string> names = field_names(py::type::of(self));
  for (const auto& group : group_names(py::type::of(self))) names.push_back(group);
  for (const auto& [key_handle, value] : fields) {
    const std::string key = py::str(key_handle);
    bool known = false;
    for (const auto& field : names) known = known || field == key;
    if (!known) {
      py::list choices;
      for (const auto& field : names) choices.append(field);
      const py::list close =
          py::module_::import("difflib").attr("get_close_matches")(key, choices, 3, 0.6);
      std::string hint;
      for (std::size_t i = 0; i < close.size(); ++i) {
        hint += (i ? ", '" : " (did you mean '") + close[i].cast<std::string>() + "'";
      }
      if (!hint.empty()) hint += "?)";
      throw py::type_error(name + "() got an unexpected keyword argument '" + key + "'" + hint);
    }
    try {
      py::setattr(self, key.c_str(), value);
    } catch (py::error_already_set& error) {
      if (!error.matches(PyExc_TypeError)) throw;
      const py::object current = self.attr(key.c_str());
      const std::string expected =
          py::isinstance<py::array>(current)
              ? std::string("an array like ") + value_repr(current)
              : std::string(py::str(py::type::of(current).attr("__name__")));
      throw py::type_error(name + "." + key + " takes " + expected + ", got " +
                           std::string(py::repr(value)) + " (" +
                           std::string(py::str(py::type::of(value).attr("__name__"))) + ")");
    }
  }
}

}  // namespace settings_detail

/// Gives the bound settings struct `cls` its keyword constructor (every field optional,
/// defaults those of the C++ struct), `__repr__` (`Name(field=value, ...)`, every field,
/// evaluable), `__eq__` (field by field), `__copy__` and `__deepcopy__`.
template <typename Params, typename... Options>
py::class_<Params, Options...>& define_settings(py::class_<Params, Options...>& cls) {
  cls.def(py::init([](const py::kwargs& fields) {
    Params params;
    settings_detail::set_fields(py::cast(&params, py::return_value_policy::reference), fields);
    return params;
  }));
  cls.def("__repr__", [](const py::object& self) {
    std::string out = settings_detail::type_name(self) + "(";
    const auto names = settings_detail::field_names(py::type::of(self));
    for (std::size_t i = 0; i < names.size(); ++i) {
      out += (i ? ", " : "") + names[i] + "=" +
             settings_detail::value_repr(self.attr(names[i].c_str()));
    }
    return out + ")";
  });
  cls.def(
      "__eq__",
      [](const py::object& self, const py::object& other) -> py::object {
        if (!py::isinstance<Params>(other))
          return py::reinterpret_borrow<py::object>(Py_NotImplemented);
        const py::object array_equal = py::module_::import("numpy").attr("array_equal");
        for (const auto& name : settings_detail::field_names(py::type::of(self))) {
          const py::object a = self.attr(name.c_str()), b = other.attr(name.c_str());
          const bool same = py::isinstance<py::array>(a) || py::isinstance<py::array>(b)
                                ? array_equal(a, b).cast<bool>()
                                : a.equal(b);
          if (!same) return py::bool_(false);
        }
        return py::bool_(true);
      },
      py::arg("other"));
  cls.def("__copy__", [](const Params& p) { return Params(p); });
  cls.def(
      "__deepcopy__", [](const Params& p, const py::dict&) { return Params(p); }, py::arg("memo"));
  return cls;
}

/// Binds the nested settings struct `member` of `cls` as the property `name` (read, a
/// reference: `params.search.hypotheses = 8` changes params; assigned, or given as the
/// keyword `Params(search=...)`, a copy of the group: as ServoParams takes its groups), and
/// each field of the group's bound class (`define_settings`, bound before) as a field of
/// `cls` of the same name that reads and writes it there (`params.hypotheses = 8`).
template <typename Params, typename Group, typename... Options>
void define_group(py::class_<Params, Options...>& cls, const char* name, Group Params::*member,
                  const char* doc) {
  cls.def_property(
      name, [member](Params& p) -> Group& { return p.*member; },
      [member](Params& p, const Group& group) { p.*member = group; },
      py::return_value_policy::reference_internal, doc);
  py::list groups;
  for (const auto& group : settings_detail::group_names(cls)) groups.append(group);
  groups.append(name);
  cls.attr("_groups") = py::tuple(groups);
  const py::handle group = py::type::of<Group>();
  const std::string group_name = name;
  for (const std::string& field : settings_detail::field_names(group)) {
    const py::cpp_function get([group_name, field](const py::object& self) {
      return py::object(self.attr(group_name.c_str()).attr(field.c_str()));
    });
    const py::cpp_function set([group_name, field](const py::object& self, const py::object& v) {
      py::setattr(self.attr(group_name.c_str()), field.c_str(), v);
    });
    const std::string field_doc = "``" + group_name + "." + field + "``";
    cls.def_property(field.c_str(), get, set, field_doc.c_str());
  }
}

}  // namespace spectral_vs::python
