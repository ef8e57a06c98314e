// Settings and passes, declared once (pbrt-v4's GetOneInt("maxdepth", 5): name and default in
// one place; Falcor's kOutputChannels; Cycles' list_render_passes). Each technique's host
// module declares one table of its settings (the fields of its Params struct in
// shaders/shared/techniques.h or guiding.h) and one of its passes; render/params.cpp puts
// them after the base path tracer's into the one list that nanobind exports
// (parallax_core.SETTINGS, PASSES) and that every layer loops over: the defaults of
// RenderParams, validation, --set, the Blender properties and panels, the EXR layer names.
#pragma once
#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace px {

enum class SettingType : uint8_t { Bool, Int, Float, Enum };
// How a setting is stored in its struct (bool and enum settings are uint32 fields).
enum class Storage : uint8_t { U32, I32, F32, None };  // None: no core field (an engine setting)

// Where a setting lives: a byte offset in its technique's Params struct (in RenderParams
// once the tables are assembled) and the field's storage.
struct FieldRef {
    size_t offset = 0;
    Storage storage = Storage::None;
};
template <class T> constexpr Storage storage_of();
template <> constexpr Storage storage_of<uint32_t>() { return Storage::U32; }
template <> constexpr Storage storage_of<int32_t>() { return Storage::I32; }
template <> constexpr Storage storage_of<float>() { return Storage::F32; }
#define PX_FIELD(STRUCT, MEMBER) \
    ::px::FieldRef { offsetof(STRUCT, MEMBER), ::px::storage_of<decltype(STRUCT::MEMBER)>() }

struct EnumItem {
    const char* name;  // what crosses the boundary (Python, --set, Blender's identifier)
    const char* label;
    const char* description;
    uint32_t value;  // the shader's constant (METHOD_MIS, ...)
};

struct SettingInfo {
    const char* name;
    SettingType type;
    FieldRef field;
    double default_value;  // bool: 0/1; enum: the default item's value
    double min, max;       // bool, enum: 0 and 0 (unused)
    std::vector<EnumItem> items;
    const char* label;
    const char* tooltip;
    // The UI panel: "sampling", "light_paths", "lights", "denoising", "ic", "adrrs", "guiding"; "": none.
    const char* panel;
    const char* technique = "";  // "base", "ic", "adrrs", "guiding" (set by the table)
    // The sub-panel inside `panel` ("": the panel itself), as the cache's "Accuracy".
    const char* group = "";
    // How a number reads: "" (plain), "time" (seconds), "length" (scene units) or "pixel".
    const char* unit = "";
    SettingInfo in_group(const char* g) && {
        group = g;
        return std::move(*this);
    }
    SettingInfo with_unit(const char* u) && {
        unit = u;
        return std::move(*this);
    }
    bool core() const { return field.storage != Storage::None; }
    const EnumItem* item(const std::string& name) const;
    const EnumItem* item(uint32_t value) const;
};

// Row builders: the tables read as name, field, default, range, label, tooltip, panel.
SettingInfo bool_setting(const char* name, FieldRef field, bool def, const char* label, const char* tooltip,
                         const char* panel);
SettingInfo int_setting(const char* name, FieldRef field, int64_t def, int64_t min, int64_t max, const char* label,
                        const char* tooltip, const char* panel);
SettingInfo float_setting(const char* name, FieldRef field, double def, double min, double max, const char* label,
                          const char* tooltip, const char* panel);
SettingInfo enum_setting(const char* name, FieldRef field, uint32_t def, std::vector<EnumItem> items,
                         const char* label, const char* tooltip, const char* panel);

struct PassInfo {
    const char* name;         // the core's name: Session.read(name)
    const char* label;        // the Blender pass and EXR layer name
    uint32_t channels;
    const char* channel_ids;  // one letter per channel (Blender's chan_id, the EXR channels)
    const char* description;
    uint32_t index;           // film slot (PASS_*)
    const char* setting;      // the setting that enables it ("": always)
    const char* technique = "";
    bool fraction = false;    // read as x / y of the sums (a ratio of counts; 0 where y is 0)
    // Made by the engine in Python, not by the film (the denoiser's Noisy Image): no film slot,
    // Session.read refuses it; exported to Python as `core` False, as the engine's settings.
    bool engine = false;
    bool core() const { return !engine; }
};

// One technique's settings (fields relative to its Params struct) and passes.
struct SettingTable {
    const char* technique;
    std::vector<SettingInfo> settings;
    std::vector<PassInfo> passes;
};

// A value from outside (Python, --set) before it is checked against its row.
struct SettingValue {
    enum Kind { Bool, Int, Float, Text, Other } kind = Other;
    double number = 0;   // Bool, Int, Float
    std::string text;    // Text
    std::string repr;    // for messages: the value as the caller wrote it
};

// Checks `value` against `row` (type, range, enum name) and writes it into the struct at
// `block` (the row's field offset is relative to it). Throws std::invalid_argument naming the
// setting, its range and the value.
void write_setting(void* block, const SettingInfo& row, const SettingValue& value);
// The stored value as a number (enum: its value).
double read_setting(const void* block, const SettingInfo& row);
// Every row's default written into the struct at `block`.
void write_defaults(void* block, const std::vector<SettingInfo>& rows);
// Every row's stored value within its range (an enum's among its items).
void check_settings(const void* block, const std::vector<SettingInfo>& rows);

}  // namespace px
