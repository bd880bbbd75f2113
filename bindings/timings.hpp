#pragma once
// What every bound stage-timings struct offers in Python, written once: its stages as
// read-only attributes, as_dict() in the order they run, and a repr with the total.

#include <pybind11/pybind11.h>

#include <cstddef>
#include <sstream>
#include <string>

namespace spectral_vs::python {

namespace py = pybind11;

/// One stage of a timings struct: its Python name, its member and its docstring.
template <typename Timings>
struct TimingField {
  const char* name;
  double Timings::*member;
  const char* doc;
};

/// Binds `Timings` (with a `total`) as `name`, its `fields` in the order the stages run.
template <typename Timings, std::size_t N>
void define_timings(py::module_& m, const char* name, const char* doc,
                    const TimingField<Timings> (&fields)[N]) {
  py::class_<Timings> timings(m, name, doc);
  for (const TimingField<Timings>& field : fields)
    timings.def_readonly(field.name, field.member, field.doc);
  timings
      .def(
          "as_dict",
          [&fields](const Timings& t) {
            py::dict d;
            for (const TimingField<Timings>& field : fields) d[field.name] = t.*field.member;
            return d;
          },
          "The stages' seconds by name, in the order they run, and the total.")
      .def("__repr__", [name = std::string(name)](const Timings& t) {
        std::ostringstream out;
        out << name << "(total=" << t.total << ")";
        return out.str();
      });
}

}  // namespace spectral_vs::python
