-- zkzap.lua: Wireshark dissector for zkzap's pcapng captures (zkzap ... --capture FILE).
-- GENERATED from zkzap's protocol tables by `python -m zkzap.docs all`; do not edit.
--
-- Link types: 147 (DLT_USER0) the ZK turbine ECU protocol, 148 (DLT_USER1) mightyZAP IR,
-- 149 (DLT_USER2) mightyZAP over Modbus RTU (the 17Lf's control table names the registers).
-- Direction: the pcapng epb_flags (inbound = device -> host, outbound = host -> device);
-- a capture of unknown direction (a sniffer on one line) is framed as a mixture.
-- Fields carry zkzap's own keys: zk.rpm, zk.egt_c, zk.engine_state_name, zap.register,
-- zapmodbus.register, zapmodbus.exception, ...
--
-- Use: wireshark -X lua_script:zkzap.lua capture.pcapng, or copy this file to
-- ~/.local/lib/wireshark/plugins/ (tshark -X lua_script:zkzap.lua -r capture.pcapng -V).

local LINKTYPE_ZK, LINKTYPE_ZAP = 147, 148
local ZK_DEFAULT_VERSION = 4
local ZK_CONTROL = {[0] = {name = "keepalive", fields = {}}, [1] = {name = "control", fields = {{key = "sw", parts = {{1, 3, 2}}, offset = 0, decimals = 0, names = {[0] = "pwm", [1] = "stop", [2] = "standby", [3] = "run"}, name_key = "state", float = false, check = {lo = 0, hi = 3}}, {key = "throttle_pct", parts = {{1, 1, 0}, {2, 7, 0}}, offset = 0, decimals = 1, scale = 0.1, float = true, check = {lo = 0, hi = 1000}}}}, [2] = {name = "action", fields = {{key = "param", parts = {{2, 7, 0}}, offset = 0, decimals = 0, names = {[1] = "drain-oil", [2] = "test-glowplug", [3] = "test-main-valve", [4] = "test-ignition-valve", [5] = "test-pump", [6] = "test-starter", [7] = "rate-20hz", [8] = "rate-50hz", [9] = "rate-100hz", [10] = "reset-fuel", [11] = "zero-thrust", [12] = "pump-on", [13] = "pump-off"}, name_key = "action", float = false, check = {lo = 1, hi = 13}}}}, [3] = {name = "unlock", fields = {}}, [4] = {name = "ignition-voltage", fields = {{key = "ignition_voltage_v", parts = {{2, 7, 0}}, offset = 0, decimals = 2, scale = 0.02, float = true}}}, [5] = {name = "accel-curve", fields = {{key = "accel_curve", parts = {{2, 7, 0}}, offset = 0, decimals = 0, scale = 1, float = false, check = {lo = 10, hi = 70}}}}, [6] = {name = "mode", fields = {{key = "rpm_factor", parts = {{2, 4, 2}}, offset = 0, decimals = 0, scale = 1, float = false, check = {lo = 0, hi = 6}}, {key = "sw", parts = {{2, 1, 0}}, offset = 0, decimals = 0, names = {[0] = "none", [1] = "stop", [2] = "standby", [3] = "run"}, name_key = "state", float = false, check = {lo = 0, hi = 3}}}}, [7] = {name = "rpm", fields = {{key = "target_rpm", parts = {{1, 3, 0}, {2, 7, 0}}, offset = 0, decimals = 0, raw_key = "rpm_value", cscale = {param = "rpm_factor", factor = 10}, float = false}}}, [8] = {name = "pressure", fields = {{key = "pressure_hpa", parts = {{1, 1, 0}, {2, 7, 0}}, offset = 0, decimals = 0, scale = 1, float = false}}}}
local ZK_STATUS = {[1] = {name = "engine", fields = {{key = "rpm", parts = {{2, 7, 0}, {1, 7, 0}}, offset = 0, decimals = 0, scale = 10, float = false}, {key = "engine_state", parts = {{3, 4, 0}}, offset = 0, decimals = 0, names = {[0] = "stop", [1] = "standby", [2] = "ignition-min-throttle", [3] = "ignition", [4] = "preheat", [5] = "fuel-ramp", [6] = "learn-max-throttle", [7] = "learn-min-throttle", [8] = "learn-idle", [9] = "running-min-throttle", [10] = "running-pump-limit", [11] = "running", [12] = "cooling", [13] = "restart", [14] = "test-glowplug", [15] = "test-main-valve", [16] = "test-ignition-valve", [17] = "test-pump", [18] = "test-starter", [19] = "fuel-exhaust-air"}, name_key = "engine_state_name", float = false, check = {lo = 0, hi = 31}}, {key = "error_code", parts = {{4, 1, 0}, {3, 7, 5}}, offset = 0, decimals = 0, names = {[0] = "none", [1] = "timeout", [2] = "voltage-low", [3] = "glowplug-failure", [4] = "pump-failure", [5] = "starter-failure", [6] = "rpm-low", [7] = "rpm-instability", [8] = "egt-high", [9] = "egt-low", [10] = "egt-sensor-failure", [11] = "ignition-valve-failure", [12] = "main-valve-failure", [13] = "loss-of-control-signal", [14] = "starter-controller-overheat", [15] = "pump-controller-overheat", [16] = "clutch-failure", [17] = "current-overload", [18] = "engine-offline"}, name_key = "error_name", float = false, check = {lo = 0, hi = 31}}, {key = "egt_c", parts = {{4, 4, 2}, {5, 7, 0}}, offset = -50, decimals = 0, scale = 1, float = false}, {key = "sw_state", parts = {{4, 6, 5}}, offset = 0, decimals = 0, names = {[0] = "stop", [1] = "standby", [2] = "run"}, name_key = "sw_state_name", float = false, check = {lo = 0, hi = 3}}}}, [2] = {name = "voltages", fields = {{key = "rpm", parts = {{2, 7, 0}, {1, 7, 0}}, offset = 0, decimals = 0, scale = 10, float = false}, {key = "radio_voltage_v", parts = {{3, 7, 0}}, offset = 0, decimals = 1, vscale = {steps = {{3, 0.1}}, default = 0.2}, float = true}, {key = "power_voltage_v", parts = {{4, 7, 0}}, offset = 0, decimals = 1, vscale = {steps = {{3, 0.1}}, default = 0.2}, float = true}, {key = "pump_voltage_v", parts = {{5, 7, 0}}, offset = 0, decimals = 1, vscale = {steps = {{3, 0.1}}, default = 0.2}, float = true}}}, [3] = {name = "throttle", fields = {{key = "rpm", parts = {{2, 7, 0}, {1, 7, 0}}, offset = 0, decimals = 0, scale = 10, float = false}, {key = "throttle_pct", parts = {{3, 7, 0}}, offset = 0, decimals = 0, scale = 1, float = false, check = {lo = 0, hi = 100}}, {key = "pressure_pa", parts = {{5, 7, 0}, {4, 7, 0}}, offset = 0, decimals = 0, scale = 2, float = false}}}, [4] = {name = "load", fields = {{key = "rpm", parts = {{2, 7, 0}, {1, 7, 0}}, offset = 0, decimals = 0, scale = 10, float = false}, {key = "current_a", parts = {{4, 0, 0}, {3, 7, 0}}, offset = 0, decimals = 1, scale = 0.1, float = true}, {key = "thrust_kg", parts = {{4, 7, 1}, {5, 7, 0}}, offset = 0, decimals = 1, since = 2, scale = 0.1, float = true}}}, [5] = {name = "ignition", fields = {{key = "rpm", parts = {{2, 7, 0}, {1, 7, 0}}, offset = 0, decimals = 0, scale = 10, float = false}, {key = "ignition_pump_voltage_v", parts = {{3, 7, 0}}, offset = 0, decimals = 2, scale = 0.02, float = true}, {key = "curve_inc", parts = {{4, 7, 0}}, offset = 0, decimals = 0, scale = 1, float = false, check = {lo = 10, hi = 70}}, {key = "curve_dec", parts = {{5, 7, 0}}, offset = 0, decimals = 0, scale = 1, float = false, check = {lo = 10, hi = 70}}}}, [6] = {name = "config", fields = {{key = "rpm", parts = {{2, 7, 0}, {1, 7, 0}}, offset = 0, decimals = 0, scale = 10, float = false}, {key = "max_rpm", parts = {{3, 7, 0}}, offset = 0, decimals = 0, scale = 1000, float = false}, {key = "max_pump_voltage_v", parts = {{4, 7, 0}}, offset = 0, decimals = 1, vscale = {steps = {{3, 0.1}}, default = 0.2}, float = true}, {key = "protocol_version", parts = {{5, 7, 2}}, offset = 0, decimals = 0, scale = 1, float = false}, {key = "status_rate_hz", parts = {{5, 1, 0}}, offset = 0, decimals = 0, values = {[0] = 20, [1] = 50, [2] = 100}, float = false, check = {lo = 0, hi = 3}}}}, [7] = {name = "fuel", fields = {{key = "rpm", parts = {{2, 7, 0}, {1, 7, 0}}, offset = 0, decimals = 0, scale = 10, float = false}, {key = "fuel_flow_l_min", parts = {{4, 1, 0}, {3, 7, 0}}, offset = 0, decimals = 2, scale = 0.01, float = true}, {key = "fuel_used_l", parts = {{5, 7, 0}, {4, 7, 2}}, offset = 0, decimals = 1, since = 2, scale = 0.1, float = true}}}, [8] = {name = "setup", fields = {{key = "rpm", parts = {{2, 7, 0}, {1, 7, 0}}, offset = 0, decimals = 0, scale = 10, float = false}, {key = "idle_rpm", parts = {{3, 7, 0}}, offset = 0, decimals = 0, scale = 1000, float = false}, {key = "esr", parts = {{4, 5, 5}}, offset = 0, decimals = 0, scale = 1, float = false}, {key = "scl", parts = {{4, 4, 4}}, offset = 0, decimals = 0, scale = 1, float = false}, {key = "startup_time_s", parts = {{4, 3, 0}, {5, 7, 0}}, offset = 0, decimals = 1, scale = 0.1, float = true}}}, [9] = {name = "ecu", fields = {{key = "rpm", parts = {{2, 7, 0}, {1, 7, 0}}, offset = 0, decimals = 0, scale = 10, float = false}, {key = "ecu_temp_c", parts = {{3, 7, 0}}, offset = -50, decimals = 0, since = 5, scale = 1, float = false}, {key = "prop_rpm", parts = {{5, 7, 0}, {4, 7, 0}}, offset = 0, decimals = 0, since = 6, scale = 1, float = false}}}, [10] = {name = "pump", fields = {{key = "rpm", parts = {{2, 7, 0}, {1, 7, 0}}, offset = 0, decimals = 0, scale = 10, float = false}, {key = "fuel_pump_rpm", parts = {{5, 7, 0}, {4, 7, 0}}, offset = 0, decimals = 0, scale = 1, float = false}}}}
local ZK_RESERVED = {[0] = {[0] = 0, [1] = 15, [2] = 255, [3] = 0}, [1] = {[0] = 0, [1] = 0, [2] = 0, [3] = 0}, [2] = {[0] = 0, [1] = 15, [2] = 0, [3] = 0}, [3] = {[0] = 0, [1] = 15, [2] = 255, [3] = 0}, [4] = {[0] = 0, [1] = 15, [2] = 0, [3] = 0}, [5] = {[0] = 0, [1] = 15, [2] = 0, [3] = 0}, [6] = {[0] = 0, [1] = 15, [2] = 224, [3] = 0}, [7] = {[0] = 0, [1] = 0, [2] = 0, [3] = 0}, [8] = {[0] = 0, [1] = 12, [2] = 0, [3] = 0}}
local ZK_FIELD_TYPES = {sw = "uint32", state = "string", throttle_pct = "double", param = "uint32", action = "string", ignition_voltage_v = "double", accel_curve = "uint32", rpm_factor = "uint32", target_rpm = "uint32", rpm_value = "uint32", pressure_hpa = "uint32", rpm = "uint32", engine_state = "uint32", engine_state_name = "string", error_code = "uint32", error_name = "string", egt_c = "int32", sw_state = "uint32", sw_state_name = "string", radio_voltage_v = "double", power_voltage_v = "double", pump_voltage_v = "double", pressure_pa = "uint32", current_a = "double", thrust_kg = "double", ignition_pump_voltage_v = "double", curve_inc = "uint32", curve_dec = "uint32", max_rpm = "uint32", max_pump_voltage_v = "double", protocol_version = "uint32", status_rate_hz = "uint32", fuel_flow_l_min = "double", fuel_used_l = "double", idle_rpm = "uint32", esr = "uint32", scl = "uint32", startup_time_s = "double", ecu_temp_c = "int32", prop_rpm = "uint32", fuel_pump_rpm = "uint32"}
local ZK_KEY_ORDER = {"rpm", "engine_state", "engine_state_name", "error_code", "error_name", "egt_c", "sw_state", "sw_state_name", "radio_voltage_v", "power_voltage_v", "pump_voltage_v", "throttle_pct", "pressure_pa", "current_a", "thrust_kg", "ignition_pump_voltage_v", "curve_inc", "curve_dec", "max_rpm", "max_pump_voltage_v", "protocol_version", "status_rate_hz", "fuel_flow_l_min", "fuel_used_l", "idle_rpm", "esr", "scl", "startup_time_s", "ecu_temp_c", "prop_rpm", "fuel_pump_rpm", "out_of_range", "sw", "state", "param", "action", "ignition_voltage_v", "accel_curve", "rpm_factor", "rpm_value", "target_rpm", "pressure_hpa"}
local ZAP_INSTRUCTIONS = {[241] = {name = "echo", title = "Echo"}, [242] = {name = "load", title = "Load Data"}, [243] = {name = "store", title = "Store Data"}, [244] = {name = "send", title = "Send Data"}, [245] = {name = "execute", title = "Execution"}, [246] = {name = "factory-reset", title = "Factory Reset"}, [248] = {name = "restart", title = "Restart"}, [115] = {name = "sync-move", title = "Symmetric Store"}}
local ZAP_REGISTERS = {[0] = {name = "model-number", size = 2, scale = 1, unit = ""}, [2] = {name = "firmware-version", size = 1, scale = 1, unit = ""}, [3] = {name = "id", size = 1, scale = 1, unit = ""}, [4] = {name = "baud-rate", size = 1, scale = 1, unit = ""}, [6] = {name = "short-stroke-limit", size = 2, scale = 1, unit = ""}, [8] = {name = "long-stroke-limit", size = 2, scale = 1, unit = ""}, [10] = {name = "protocol-type", size = 1, scale = 1, unit = ""}, [12] = {name = "lowest-limit-voltage", size = 1, scale = 0.1, unit = "V"}, [13] = {name = "highest-limit-voltage", size = 1, scale = 0.1, unit = "V"}, [14] = {name = "motor-operating-rate-limit", size = 2, scale = 1, unit = ""}, [16] = {name = "feedback-return-mode", size = 1, scale = 1, unit = ""}, [17] = {name = "alarm-led", size = 1, scale = 1, unit = ""}, [18] = {name = "alarm-shutdown", size = 1, scale = 1, unit = ""}, [19] = {name = "start-compliance-margin", size = 1, scale = 1, unit = ""}, [20] = {name = "end-compliance-margin", size = 1, scale = 1, unit = ""}, [21] = {name = "speed-limit", size = 2, scale = 1, unit = ""}, [24] = {name = "calibration-short-stroke", size = 2, scale = 1, unit = ""}, [26] = {name = "calibration-long-stroke", size = 2, scale = 1, unit = ""}, [33] = {name = "acceleration", size = 1, scale = 1, unit = ""}, [34] = {name = "deceleration", size = 1, scale = 1, unit = ""}, [35] = {name = "current-i-gain", size = 1, scale = 1, unit = ""}, [36] = {name = "current-p-gain", size = 1, scale = 1, unit = ""}, [37] = {name = "speed-d-gain", size = 1, scale = 1, unit = ""}, [38] = {name = "speed-i-gain", size = 1, scale = 1, unit = ""}, [39] = {name = "speed-p-gain", size = 1, scale = 1, unit = ""}, [46] = {name = "min-position-calibration", size = 1, scale = 1, unit = ""}, [47] = {name = "max-position-calibration", size = 1, scale = 1, unit = ""}, [52] = {name = "current-limit", size = 2, scale = 1, unit = "mA"}, [128] = {name = "force-on-off", size = 1, scale = 1, unit = ""}, [129] = {name = "led", size = 1, scale = 1, unit = ""}, [134] = {name = "goal-position", size = 2, scale = 1, unit = ""}, [136] = {name = "goal-speed", size = 2, scale = 1, unit = ""}, [138] = {name = "goal-current", size = 2, scale = 1, unit = "mA"}, [140] = {name = "present-position", size = 2, scale = 1, unit = ""}, [142] = {name = "present-current", size = 2, scale = 1, unit = "mA"}, [144] = {name = "present-motor-operating-rate", size = 2, scale = 1, unit = ""}, [146] = {name = "present-voltage", size = 1, scale = 0.1, unit = "V"}, [150] = {name = "moving", size = 1, scale = 1, unit = ""}, [147] = {name = "present-temperature", size = 1, scale = 1, unit = ""}, [148] = {name = "registered-instruction", size = 1, scale = 1, unit = ""}, [151] = {name = "lock", size = 1, scale = 1, unit = ""}}
local ZAP_ERROR_BITS = {[5] = "overload", [0] = "input-voltage"}
local ZAP_BROADCAST = 254
local LINKTYPE_MODBUS = 149
local MB_MAP = "17Lf"
local MB_REGISTERS = {[0] = {name = "model-number", scale = 1, unit = ""}, [1] = {name = "firmware-version", scale = 1, unit = ""}, [4] = {name = "id", scale = 1, unit = ""}, [5] = {name = "baud-rate", scale = 1, unit = ""}, [9] = {name = "alarm-led", scale = 1, unit = ""}, [10] = {name = "alarm-shutdown", scale = 1, unit = ""}, [11] = {name = "short-stroke-limit", scale = 1, unit = ""}, [12] = {name = "long-stroke-limit", scale = 1, unit = ""}, [13] = {name = "start-compliance-margin", scale = 1, unit = ""}, [14] = {name = "end-compliance-margin", scale = 1, unit = ""}, [15] = {name = "acceleration", scale = 1, unit = ""}, [16] = {name = "deceleration", scale = 1, unit = ""}, [17] = {name = "min-position-calibration", scale = 1, unit = ""}, [18] = {name = "max-position-calibration", scale = 1, unit = ""}, [19] = {name = "motor-operating-rate-limit", scale = 1, unit = ""}, [20] = {name = "speed-limit", scale = 1, unit = ""}, [21] = {name = "current-limit", scale = 1, unit = "mA"}, [22] = {name = "current-i-gain", scale = 1, unit = ""}, [23] = {name = "current-p-gain", scale = 1, unit = ""}, [24] = {name = "speed-d-gain", scale = 1, unit = ""}, [25] = {name = "speed-i-gain", scale = 1, unit = ""}, [26] = {name = "speed-p-gain", scale = 1, unit = ""}, [40] = {name = "indirect-address-0", scale = 1, unit = ""}, [41] = {name = "indirect-address-1", scale = 1, unit = ""}, [42] = {name = "indirect-address-2", scale = 1, unit = ""}, [43] = {name = "indirect-address-3", scale = 1, unit = ""}, [44] = {name = "indirect-address-4", scale = 1, unit = ""}, [45] = {name = "indirect-address-5", scale = 1, unit = ""}, [46] = {name = "indirect-address-6", scale = 1, unit = ""}, [47] = {name = "indirect-address-7", scale = 1, unit = ""}, [48] = {name = "indirect-address-8", scale = 1, unit = ""}, [49] = {name = "indirect-address-9", scale = 1, unit = ""}, [50] = {name = "extended-io-0", scale = 1, unit = ""}, [51] = {name = "extended-io-1", scale = 1, unit = ""}, [52] = {name = "extended-io-2", scale = 1, unit = ""}, [53] = {name = "extended-io-3", scale = 1, unit = ""}, [60] = {name = "action-0-type", scale = 1, unit = ""}, [61] = {name = "action-0-distance", scale = 1, unit = ""}, [62] = {name = "action-0-repeat-type", scale = 1, unit = ""}, [63] = {name = "action-0-repeat-count", scale = 1, unit = ""}, [64] = {name = "action-0-repeat-time", scale = 1, unit = ""}, [65] = {name = "action-0-goal-speed", scale = 1, unit = ""}, [66] = {name = "action-0-goal-current", scale = 1, unit = ""}, [67] = {name = "action-0-acceleration", scale = 1, unit = ""}, [68] = {name = "action-0-deceleration", scale = 1, unit = ""}, [69] = {name = "action-0-stop", scale = 1, unit = ""}, [70] = {name = "action-1-type", scale = 1, unit = ""}, [71] = {name = "action-1-distance", scale = 1, unit = ""}, [72] = {name = "action-1-repeat-type", scale = 1, unit = ""}, [73] = {name = "action-1-repeat-count", scale = 1, unit = ""}, [74] = {name = "action-1-repeat-time", scale = 1, unit = ""}, [75] = {name = "action-1-goal-speed", scale = 1, unit = ""}, [76] = {name = "action-1-goal-current", scale = 1, unit = ""}, [77] = {name = "action-1-acceleration", scale = 1, unit = ""}, [78] = {name = "action-1-deceleration", scale = 1, unit = ""}, [79] = {name = "action-1-stop", scale = 1, unit = ""}, [80] = {name = "action-2-type", scale = 1, unit = ""}, [81] = {name = "action-2-distance", scale = 1, unit = ""}, [82] = {name = "action-2-repeat-type", scale = 1, unit = ""}, [83] = {name = "action-2-repeat-count", scale = 1, unit = ""}, [84] = {name = "action-2-repeat-time", scale = 1, unit = ""}, [85] = {name = "action-2-goal-speed", scale = 1, unit = ""}, [86] = {name = "action-2-goal-current", scale = 1, unit = ""}, [87] = {name = "action-2-acceleration", scale = 1, unit = ""}, [88] = {name = "action-2-deceleration", scale = 1, unit = ""}, [89] = {name = "action-2-stop", scale = 1, unit = ""}, [90] = {name = "action-3-type", scale = 1, unit = ""}, [91] = {name = "action-3-distance", scale = 1, unit = ""}, [92] = {name = "action-3-repeat-type", scale = 1, unit = ""}, [93] = {name = "action-3-repeat-count", scale = 1, unit = ""}, [94] = {name = "action-3-repeat-time", scale = 1, unit = ""}, [95] = {name = "action-3-goal-speed", scale = 1, unit = ""}, [96] = {name = "action-3-goal-current", scale = 1, unit = ""}, [97] = {name = "action-3-acceleration", scale = 1, unit = ""}, [98] = {name = "action-3-deceleration", scale = 1, unit = ""}, [99] = {name = "action-3-stop", scale = 1, unit = ""}, [100] = {name = "action-4-type", scale = 1, unit = ""}, [101] = {name = "action-4-distance", scale = 1, unit = ""}, [102] = {name = "action-4-repeat-type", scale = 1, unit = ""}, [103] = {name = "action-4-repeat-count", scale = 1, unit = ""}, [104] = {name = "action-4-repeat-time", scale = 1, unit = ""}, [105] = {name = "action-4-goal-speed", scale = 1, unit = ""}, [106] = {name = "action-4-goal-current", scale = 1, unit = ""}, [107] = {name = "action-4-acceleration", scale = 1, unit = ""}, [108] = {name = "action-4-deceleration", scale = 1, unit = ""}, [109] = {name = "action-4-stop", scale = 1, unit = ""}, [200] = {name = "force-on-off", scale = 1, unit = ""}, [201] = {name = "pause", scale = 1, unit = ""}, [202] = {name = "stop", scale = 1, unit = ""}, [203] = {name = "led", scale = 1, unit = ""}, [204] = {name = "hardware-error", scale = 1, unit = ""}, [205] = {name = "goal-position", scale = 1, unit = ""}, [208] = {name = "goal-speed", scale = 1, unit = ""}, [209] = {name = "goal-current", scale = 1, unit = "mA"}, [210] = {name = "present-position", scale = 1, unit = ""}, [211] = {name = "present-current", scale = 1, unit = "mA"}, [213] = {name = "present-motor-operating-rate", scale = 1, unit = ""}, [214] = {name = "present-voltage", scale = 1, unit = ""}, [215] = {name = "moving", scale = 1, unit = ""}, [220] = {name = "action-enable", scale = 1, unit = ""}, [240] = {name = "indirect-data-0", scale = 1, unit = ""}, [241] = {name = "indirect-data-1", scale = 1, unit = ""}, [242] = {name = "indirect-data-2", scale = 1, unit = ""}, [243] = {name = "indirect-data-3", scale = 1, unit = ""}, [244] = {name = "indirect-data-4", scale = 1, unit = ""}, [245] = {name = "indirect-data-5", scale = 1, unit = ""}, [246] = {name = "indirect-data-6", scale = 1, unit = ""}, [247] = {name = "indirect-data-7", scale = 1, unit = ""}, [248] = {name = "indirect-data-8", scale = 1, unit = ""}, [249] = {name = "indirect-data-9", scale = 1, unit = ""}}
local MB_FUNCTIONS = {[3] = "read", [6] = "write", [16] = "write-multiple"}
local MB_FUNCTION_TITLES = {[3] = "Read Holding Registers", [6] = "Write Single Register", [16] = "Write Multiple Registers"}
local MB_EXCEPTIONS = {[1] = {name = "illegal-function", meaning = "illegal function: the actuator does not know this function code"}, [2] = {name = "illegal-data-address", meaning = "illegal data address: no such register, or a block past the table"}, [3] = {name = "illegal-data-value", meaning = "illegal data value: a value or register count it does not take"}, [4] = {name = "slave-device-failure", meaning = "slave device failure (the manual: a parameter out of range)"}, [5] = {name = "acknowledge", meaning = "acknowledge (the manual: data not ready)"}, [6] = {name = "slave-device-busy", meaning = "slave device busy (the manual: parameters locked)"}}
local MB_MAX_ID = 247
local MB_FIELD_KINDS = {{"kind", "string"}, {"id", "uint8"}, {"function", "string"}, {"code", "hex8"}, {"exception", "uint8"}, {"name", "string"}, {"meaning", "string"}, {"register", "string"}, {"address", "uint16"}, {"count", "uint16"}, {"value", "uint32"}, {"physical", "double"}, {"unit", "string"}, {"values", "string"}, {"malformed", "string"}, {"params", "string"}, {"dir", "string"}, {"latency_ms", "double"}}

-- ---------------------------------------------------------------------------------------------
-- runtime

local zk_proto = Proto("zk", "ZK turbine ECU protocol (zkzap)")
local zap_proto = Proto("zap", "mightyZAP IR protocol (zkzap)")
local mb_proto = Proto("zapmodbus", "mightyZAP Modbus RTU (zkzap)")

local f_dir = Field.new("frame.packet_flags_direction")
local f_if = Field.new("frame.interface_id")

local ZK_F = {
  frame = ProtoField.bytes("zk.frame", "ZK frame", base.SPACE),
  kind = ProtoField.string("zk.kind", "kind"),
  id = ProtoField.uint8("zk.id", "id"),
  command = ProtoField.string("zk.command", "command"),
  payload = ProtoField.string("zk.payload", "payload"),
  reserved = ProtoField.string("zk.reserved", "reserved"),
  out_of_range = ProtoField.string("zk.out_of_range", "out_of_range"),
  dir = ProtoField.string("zk.dir", "dir"),
  crc = ProtoField.uint8("zk.crc", "crc", base.HEX),
  crc_ok = ProtoField.bool("zk.crc_ok", "crc_ok"),
  bad = ProtoField.bytes("zk.bad", "bad frame", base.SPACE),
}
for key, kind in pairs(ZK_FIELD_TYPES) do
  if ZK_F[key] == nil then
    if kind == "double" then ZK_F[key] = ProtoField.double("zk." .. key, key)
    elseif kind == "int32" then ZK_F[key] = ProtoField.int32("zk." .. key, key)
    elseif kind == "string" then ZK_F[key] = ProtoField.string("zk." .. key, key)
    else ZK_F[key] = ProtoField.uint32("zk." .. key, key) end
  end
end
local zk_fields = {}
for _, f in pairs(ZK_F) do zk_fields[#zk_fields + 1] = f end
zk_proto.fields = zk_fields

local ZAP_F = {
  frame = ProtoField.bytes("zap.frame", "mightyZAP packet", base.SPACE),
  kind = ProtoField.string("zap.kind", "kind"),
  id = ProtoField.uint8("zap.id", "id"),
  instruction = ProtoField.string("zap.instruction", "instruction"),
  code = ProtoField.uint8("zap.code", "code", base.HEX),
  error = ProtoField.uint8("zap.error", "error", base.HEX),
  errors = ProtoField.string("zap.errors", "errors"),
  params = ProtoField.string("zap.params", "params"),
  address = ProtoField.uint8("zap.address", "address", base.HEX),
  register = ProtoField.string("zap.register", "register"),
  length = ProtoField.uint8("zap.length", "length"),
  value = ProtoField.uint32("zap.value", "value"),
  physical = ProtoField.double("zap.physical", "physical"),
  unit = ProtoField.string("zap.unit", "unit"),
  values = ProtoField.string("zap.values", "values"),
  targets = ProtoField.string("zap.targets", "targets"),
  reset_id = ProtoField.bool("zap.reset_id", "reset_id"),
  reset_baud = ProtoField.bool("zap.reset_baud", "reset_baud"),
  malformed = ProtoField.string("zap.malformed", "malformed"),
  dir = ProtoField.string("zap.dir", "dir"),
  checksum = ProtoField.uint8("zap.checksum", "checksum", base.HEX),
  checksum_ok = ProtoField.bool("zap.checksum_ok", "checksum_ok"),
  request_in = ProtoField.framenum("zap.request_in", "request in", base.NONE, frametype.REQUEST),
  response_in = ProtoField.framenum("zap.response_in", "response in", base.NONE, frametype.RESPONSE),
  latency_ms = ProtoField.double("zap.latency_ms", "latency_ms"),
  bad = ProtoField.bytes("zap.bad", "bad packet", base.SPACE),
}
local zap_fields = {}
for _, f in pairs(ZAP_F) do zap_fields[#zap_fields + 1] = f end
zap_proto.fields = zap_fields

local ex_zk_crc = ProtoExpert.new("zk.crc_bad", "ZK frame CRC mismatch", expert.group.CHECKSUM, expert.severity.WARN)
local ex_zap_chk = ProtoExpert.new("zap.checksum_bad", "mightyZAP checksum mismatch", expert.group.CHECKSUM,
                                   expert.severity.WARN)
local ex_zap_nopair = ProtoExpert.new("zap.unpaired", "feedback without a request from this ID",
                                      expert.group.SEQUENCE, expert.severity.NOTE)
zk_proto.experts = {ex_zk_crc}
zap_proto.experts = {ex_zap_chk, ex_zap_nopair}

-- the byte table of a reflected CRC of polynomial poly (0x8C: CRC-8/MAXIM-DOW, 0xA001: CRC-16/MODBUS)
local function crc_table(poly)
  local t = {}
  for i = 0, 255 do
    local c = i
    for _ = 1, 8 do
      if c % 2 == 1 then c = bit32.bxor(bit32.rshift(c, 1), poly) else c = bit32.rshift(c, 1) end
    end
    t[i] = c
  end
  return t
end
local CRC = crc_table(0x8C)
local function crc8(b, first, last)
  local c = 0
  for i = first, last do c = CRC[bit32.bxor(c, b[i])] end
  return c
end

local function hex(b, first, last)
  local t = {}
  for i = first, last do t[#t + 1] = string.format("%02X", b[i]) end
  return table.concat(t, " ")
end

local function round(x, d)
  local m = 10 ^ d
  local v = x * m
  if v >= 0 then return math.floor(v + 0.5) / m end
  return -math.floor(-v + 0.5) / m
end

local function raw_of(b, parts)   -- b: 0-based frame bytes
  local v = 0
  for _, p in ipairs(parts) do
    local width = p[2] - p[3] + 1
    v = v * 2 ^ width + bit32.extract(b[p[1]], p[3], width)
  end
  return v
end

-- state of the first pass, by packet number: what each packet completed
local results = {}
local streams = {}

local function reset_state()
  results = {}
  streams = {}
  ZK_STATE = {version = nil, known = nil, source = "default", rpm_factor = nil}
  ZAP_STATE = {load = {}, pending = {}, response_of = {}}
  MB_STATE = {request = {}, pending = {}, response_of = {}}
end
reset_state()
function zk_proto.init() reset_state() end
function zap_proto.init() reset_state() end
function mb_proto.init() reset_state() end

local function direction(pinfo)
  local d = f_dir()
  if d ~= nil then
    local v = d.value
    if v == 1 then return 1 end
    if v == 2 then return 2 end
  end
  return 0
end

local function stream_of(prefix, pinfo)
  local i = f_if()
  local key = prefix .. ":" .. tostring(i and i.value or 0) .. ":" .. direction(pinfo)
  local s = streams[key]
  if s == nil then
    s = {buf = {}, n = 0}
    streams[key] = s
  end
  return s
end

-- append this packet's bytes to the stream; returns the 1-based buffer and the index of the
-- packet's first byte in it
local function feed(s, tvb)
  local buf = s.buf
  local start = #buf + 1
  for i = 0, tvb:len() - 1 do buf[#buf + 1] = tvb(i, 1):uint() end
  return buf, start
end

local function keep_from(s, pos)
  local buf, out = s.buf, {}
  for i = pos, #buf do out[#out + 1] = buf[i] end
  s.buf = out
end

local function frame_bytes(buf, p, n)   -- 0-based copy of buf[p .. p+n-1]
  local b = {}
  for i = 0, n - 1 do b[i] = buf[p + i] end
  return b
end

local function item_range(tvb, item, label)   -- the frame in this packet, or reassembled
  if item.offset ~= nil then return tvb(item.offset, item.len) end
  local hexs = {}
  for i = 0, item.len - 1 do hexs[#hexs + 1] = string.format("%02X", item.bytes[i]) end
  return ByteArray.new(table.concat(hexs, " ")):tvb(label)()
end

-- the first pass over a packet: feed its bytes to its stream and cut the frames they complete
-- (scan(buf, aligned, dir) -> found, rest, aligned), one item each; handle(item, b, dir)
-- decodes a whole one (b: its 0-based bytes, b.n its length). Kept by packet number.
local function first_pass(prefix, scan, tvb, pinfo, handle)
  local res = {}
  local dir = direction(pinfo)
  local s = stream_of(prefix, pinfo)
  local buf, start = feed(s, tvb)
  local found, rest, aligned = scan(buf, s.aligned, dir)
  s.aligned = aligned
  for _, fr in ipairs(found) do
    local b = frame_bytes(buf, fr.pos, fr.len)
    b.n = fr.len
    local item = {bytes = b, len = fr.len, ok = fr.ok, expected = fr.expected, found = fr.found,
                  offset = fr.pos >= start and fr.pos - start or nil}
    handle(item, b, dir)
    res[#res + 1] = item
  end
  keep_from(s, rest)
  results[pinfo.number] = res
  return res
end

-- a bus's pairing of replies to requests (st: its pending requests and response_of): a request
-- to ID ident waits for its reply; a reply from ident takes the request waiting for it, with the
-- latency between them (none where both carry one time stamp)
local function pair_request(st, ident, pinfo)
  st.pending[ident] = {num = pinfo.number, ts = pinfo.abs_ts}
end

local function pair_reply(st, item, ident, pinfo)
  local p = st.pending[ident]
  st.pending[ident] = nil
  if p ~= nil then
    item.request_in = p.num
    -- (one time stamp: request and reply came in one read, the latency is not known, never 0)
    if p.ts < pinfo.abs_ts then item.latency_ms = round((pinfo.abs_ts - p.ts) * 1000, 3) end
    st.response_of[p.num] = pinfo.number
  end
end

-- a reply's link to its request and its latency (or a note that it has none); a request's link
-- to its reply (F: the protocol's fields; response_of: request packet -> reply packet)
local function add_links(t, F, item, is_request, response_of, pinfo, ex_nopair)
  if item.request_in ~= nil then
    t:add(F.request_in, item.request_in)
    t:add(F.latency_ms, item.latency_ms)
  elseif not is_request then
    t:add_proto_expert_info(ex_nopair)
  end
  local resp = response_of[pinfo.number]
  if is_request and resp ~= nil then t:add(F.response_in, resp) end
end

-- ZK ------------------------------------------------------------------------------------------

local function zk_decode_fields(fields, b, ctx, known, out)
  local bad = {}
  for _, f in ipairs(fields) do
    local r = raw_of(b, f.parts)
    if f.since ~= nil and known ~= nil and known < f.since then
      out[#out + 1] = {f.key, nil}
      if f.name_key then out[#out + 1] = {f.name_key, nil} end
    else
      if f.check and (r < f.check.lo or r > f.check.hi or (f.names and f.names[r] == nil)
                      or (f.values and f.values[r] == nil)) then
        bad[#bad + 1] = f.key
      end
      if f.raw_key then out[#out + 1] = {f.raw_key, r} end
      if f.values then
        out[#out + 1] = {f.key, f.values[r]}
      elseif f.names then
        out[#out + 1] = {f.key, r}
        out[#out + 1] = {f.name_key, f.names[r] or ("undocumented-" .. r)}
      else
        local s = f.scale
        if f.vscale then
          s = f.vscale.default
          for _, step in ipairs(f.vscale.steps) do
            if ctx.version ~= nil and ctx.version <= step[1] then s = step[2]; break end
          end
        elseif f.cscale then
          local p = ctx[f.cscale.param]
          if p == nil or p == 0 then s = nil else s = f.cscale.factor * p end
        end
        if s == nil then
          out[#out + 1] = {f.key, nil}
        else
          local v = r * s + f.offset
          if f.float then v = round(v, f.decimals) end
          out[#out + 1] = {f.key, v}
        end
      end
    end
  end
  if #bad > 0 then out[#out + 1] = {"out_of_range", table.concat(bad, ",")} end
end

local function zk_decode(b, n)
  local st = ZK_STATE
  local out = {}
  if n == 7 then
    local sid = b[0] % 16
    out[#out + 1] = {"kind", "status"}
    out[#out + 1] = {"id", sid}
    local frame = ZK_STATUS[sid]
    if frame == nil then
      out[#out + 1] = {"rpm", (b[2] * 256 + b[1]) * 10}
      out[#out + 1] = {"payload", hex(b, 3, 5)}
      return out
    end
    local version, known = st.version or ZK_DEFAULT_VERSION, st.known
    if sid == 6 then
      version = bit32.rshift(b[5], 2)
      known = version
      st.version, st.known, st.source = version, version, "frame"
    end
    zk_decode_fields(frame.fields, b, {version = version}, known, out)
    return out
  end
  local cid = bit32.rshift(b[1], 4)
  out[#out + 1] = {"kind", "control"}
  out[#out + 1] = {"id", cid}
  local cmd = ZK_CONTROL[cid]
  if cmd == nil then
    out[#out + 1] = {"command", nil}
    out[#out + 1] = {"payload", string.format("%X%02X", b[1] % 16, b[2])}
    return out
  end
  out[#out + 1] = {"command", cmd.name}
  zk_decode_fields(cmd.fields, b, {rpm_factor = st.rpm_factor}, nil, out)
  if cid == 6 then
    for _, kv in ipairs(out) do if kv[1] == "rpm_factor" then st.rpm_factor = kv[2] end end
  end
  local res = {}
  for byte, mask in pairs(ZK_RESERVED[cid] or {}) do
    local v = bit32.band(b[byte], mask)
    if v ~= 0 then res[#res + 1] = {byte, string.format("b%d=0x%02x", byte, v)} end
  end
  if #res > 0 then
    table.sort(res, function(x, y) return x[1] < y[1] end)
    local t = {}
    for _, x in ipairs(res) do t[#t + 1] = x[2] end
    out[#out + 1] = {"reserved", table.concat(t, " ")}
  end
  return out
end

-- scan a ZK stream: complete frames (and CRC failures at frame boundaries). ``aligned`` says
-- whether the stream was at a frame boundary where the previous packet's scan stopped (false
-- after a bad frame: the bytes held back then are not reported as a second one); the scan
-- returns it for the next packet, as zk decode's framer keeps it from one read to the next.
local function zk_scan(buf, dir, aligned)
  local want_control = dir ~= 1
  local want_status = dir ~= 2
  local found, i, n = {}, 1, #buf
  if aligned == nil then aligned = true end
  while i <= n do
    local h = buf[i]
    local need = nil
    if want_control and h == 0xFF then need = 4
    elseif want_status and h >= 0xF1 and h <= 0xFE then need = 7 end
    if need ~= nil and i + need - 1 > n then break end      -- wait for the rest
    local ok = false
    if need == 4 then
      ok = crc8(buf, i + 1, i + 2) == buf[i + 3] and bit32.rshift(buf[i + 1], 4) <= 8
    elseif need == 7 then
      ok = crc8(buf, i, i + 5) == buf[i + 6]
    end
    if ok then
      found[#found + 1] = {pos = i, len = need, ok = true}
      i = i + need
      aligned = true
    else
      if need ~= nil and aligned then
        local expected = need == 4 and crc8(buf, i + 1, i + 2) or crc8(buf, i, i + 5)
        found[#found + 1] = {pos = i, len = need, ok = false, expected = expected}
      end
      aligned = false
      i = i + 1
    end
  end
  return found, i, aligned
end

local ZK_NAMES = {[0] = "keepalive"}
local function zk_summary(values)
  local kind, id, extra = nil, nil, nil
  for _, kv in ipairs(values) do
    if kv[1] == "kind" then kind = kv[2] elseif kv[1] == "id" then id = kv[2]
    elseif kv[1] == "command" then extra = kv[2] end
  end
  if kind == "control" then return string.format("control ID %d %s", id, extra or "?") end
  local st = ZK_STATUS[id]
  return string.format("status ID %d %s", id, st and st.name or "?")
end

function zk_proto.dissector(tvb, pinfo, tree)
  pinfo.cols.protocol = "ZK"
  local res = results[pinfo.number]
  if res == nil then
    res = first_pass("zk", function(buf, aligned, dir) return zk_scan(buf, dir, aligned) end, tvb, pinfo,
                     function(item, b)
      if item.ok then item.values = zk_decode(b, item.len) end
      item.dir = (item.len == 4) and "h2d" or "d2h"
    end)
  end
  local info = {}
  for _, item in ipairs(res) do
    local range = item_range(tvb, item, "reassembled ZK frame")
    if item.ok then
      local t = tree:add(zk_proto, range, "ZK " .. zk_summary(item.values))
      t:add(ZK_F.frame, range)
      t:add(ZK_F.dir, item.dir)
      for _, kv in ipairs(item.values) do
        local f = ZK_F[kv[1]]
        if f ~= nil and kv[2] ~= nil then t:add(f, kv[2]) end
      end
      t:add(ZK_F.crc, item.bytes[item.len - 1])
      t:add(ZK_F.crc_ok, true)
      info[#info + 1] = zk_summary(item.values)
    else
      local t = tree:add(zk_proto, range, "bad ZK frame")
      t:add(ZK_F.bad, range)
      t:add(ZK_F.crc_ok, false)
      t:add_proto_expert_info(ex_zk_crc, string.format("CRC mismatch: expected %02X, found %02X",
                                                        item.expected, item.bytes[item.len - 1]))
      info[#info + 1] = "bad CRC"
    end
  end
  pinfo.cols.info = (#info > 0) and table.concat(info, "; ") or "(part of a frame)"
  return tvb:len()
end

-- mightyZAP -----------------------------------------------------------------------------------

local function zap_register_values(address, data)   -- data: 1-based list
  local out, i = {}, 1
  while i <= #data do
    local addr = address + i - 1
    local reg = ZAP_REGISTERS[addr]
    if reg ~= nil and i + reg.size - 1 <= #data then
      local raw = 0
      for k = reg.size - 1, 0, -1 do raw = raw * 256 + data[i + k] end
      out[#out + 1] = {reg = reg, name = reg.name, raw = raw}
      i = i + reg.size
    else
      local name = reg == nil and string.format("0x%02x", addr) or (reg.name .. "(partial)")
      out[#out + 1] = {name = name, raw = data[i], reg = {scale = 1, unit = ""}}
      i = i + 1
    end
  end
  return out
end

local function zap_with_register(out, address, data)
  local values = zap_register_values(address, data)
  out[#out + 1] = {"address", address}
  if #values == 1 then
    local v = values[1]
    out[#out + 1] = {"register", v.name}
    out[#out + 1] = {"value", v.raw}
    if v.reg.scale ~= 1 then
      out[#out + 1] = {"physical", round(v.raw * v.reg.scale, 3)}
      out[#out + 1] = {"unit", v.reg.unit}
    end
  else
    local names, kv = {}, {}
    for _, v in ipairs(values) do
      names[#names + 1] = v.name
      kv[#kv + 1] = v.name .. "=" .. v.raw
    end
    out[#out + 1] = {"register", table.concat(names, ",")}
    out[#out + 1] = {"values", table.concat(kv, ";")}
  end
end

local function zap_decode(b, n, request)
  local ident, code = b[3], b[5]
  local params = {}
  for i = 6, n - 2 do params[#params + 1] = b[i] end
  local phex = hex(b, 6, n - 2)
  local out = {}
  local ins = ZAP_INSTRUCTIONS[code]
  if ins ~= nil then
    out[#out + 1] = {"kind", "command"}
    out[#out + 1] = {"id", ident}
    out[#out + 1] = {"instruction", ins.name}
    out[#out + 1] = {"code", code}
    out[#out + 1] = {"params", phex}
    if code == 0xF2 and #params == 2 then
      local reg = ZAP_REGISTERS[params[1]]
      out[#out + 1] = {"address", params[1]}
      out[#out + 1] = {"register", reg and reg.name or string.format("0x%02x", params[1])}
      out[#out + 1] = {"length", params[2]}
    elseif (code == 0xF3 or code == 0xF4) and #params >= 2 then
      local data = {}
      for i = 2, #params do data[#data + 1] = params[i] end
      zap_with_register(out, params[1], data)
    elseif code == 0xF6 and #params == 1 then
      out[#out + 1] = {"reset_id", bit32.band(params[1], 1) ~= 0}
      out[#out + 1] = {"reset_baud", bit32.band(params[1], 2) ~= 0}
    elseif code == 0x73 and #params >= 2 then
      local addr, length = params[1], params[2]
      local reg = ZAP_REGISTERS[addr]
      out[#out + 1] = {"address", addr}
      out[#out + 1] = {"register", reg and reg.name or string.format("0x%02x", addr)}
      out[#out + 1] = {"length", length}
      local body = #params - 2
      local step = 1 + length
      if length > 0 and body % step == 0 then
        local t = {}
        for j = 3, #params, step do
          local v = 0
          for k = step - 1, 1, -1 do v = v * 256 + params[j + k] end
          t[#t + 1] = params[j] .. "=" .. v
        end
        out[#out + 1] = {"targets", table.concat(t, ";")}
      else
        out[#out + 1] = {"malformed", string.format("%d data bytes are not a multiple of %d", body, step)}
      end
    end
    return out
  end
  out[#out + 1] = {"kind", "feedback"}
  out[#out + 1] = {"id", ident}
  out[#out + 1] = {"error", code}
  local names = {}
  for bitno, name in pairs(ZAP_ERROR_BITS) do
    if bit32.band(code, 2 ^ bitno) ~= 0 then names[#names + 1] = {bitno, name} end
  end
  table.sort(names, function(x, y) return x[1] > y[1] end)     -- zkzap's order: overload, input-voltage
  local t = {}
  for _, x in ipairs(names) do t[#t + 1] = x[2] end
  local other = bit32.band(code, bit32.bnot(0x21))
  if other ~= 0 then t[#t + 1] = string.format("undocumented-0x%02x", other) end
  out[#out + 1] = {"errors", table.concat(t, ",")}
  out[#out + 1] = {"params", phex}
  if request ~= nil and #params > 0 and request[5] == 0xF2 and request.n == 9 then
    zap_with_register(out, request[6], params)
  elseif (#params == 1 or #params == 2) and request == nil then
    local v = 0
    for k = #params, 1, -1 do v = v * 256 + params[k] end
    out[#out + 1] = {"value", v}
  end
  return out
end

local function zap_scan(buf, aligned)          -- aligned: as zk_scan's
  local found, i, n = {}, 1, #buf
  if aligned == nil then aligned = true end
  while i <= n do
    if buf[i] == 0xFF then
      -- the header is the last three FFs of a run
      local p = i
      while p + 3 <= n and buf[p + 3] == 0xFF do p = p + 1 end
      if p + 4 > n then break end                          -- header, ID or SIZE still to come
      if buf[p + 1] == 0xFF and buf[p + 2] == 0xFF and buf[p + 3] ~= 0xFF and buf[p + 4] >= 2 then
        local len = buf[p + 4] + 5
        if p + len - 1 > n then break end
        local sum = 0
        for k = p + 3, p + len - 2 do sum = sum + buf[k] end
        local chk = 0xFF - (sum % 256)
        if chk == buf[p + len - 1] then
          if p > i then aligned = false end
          found[#found + 1] = {pos = p, len = len, ok = true}
          i = p + len
          aligned = true
        else
          if aligned then found[#found + 1] = {pos = p, len = len, ok = false, expected = chk} end
          aligned = false
          i = p + 1
        end
      elseif p + 2 > n then
        break
      else
        aligned = false
        i = i + 1
      end
    else
      aligned = false
      i = i + 1
    end
  end
  return found, i, aligned
end

function zap_proto.dissector(tvb, pinfo, tree)
  pinfo.cols.protocol = "mightyZAP"
  local res = results[pinfo.number]
  local st = ZAP_STATE
  if res == nil then
    res = first_pass("zap", zap_scan, tvb, pinfo, function(item, b, dir)
      if not item.ok then return end
      local ident, code = b[3], b[5]
      if ZAP_INSTRUCTIONS[code] ~= nil then
        item.values = zap_decode(b, item.len, nil)
        if code == 0xF2 then st.load[ident] = b else st.load[ident] = nil end
        if dir ~= 1 and ident ~= ZAP_BROADCAST then pair_request(st, ident, pinfo) end
        item.dir = "h2d"
      else
        local req = st.load[ident]
        st.load[ident] = nil
        item.values = zap_decode(b, item.len, req)
        pair_reply(st, item, ident, pinfo)
        item.dir = "d2h"
      end
    end)
  end
  local info = {}
  for _, item in ipairs(res) do
    local range = item_range(tvb, item, "reassembled mightyZAP packet")
    if item.ok then
      local summary
      local v = {}
      for _, kv in ipairs(item.values) do v[kv[1]] = kv[2] end
      if v.kind == "command" then
        summary = string.format("%s to ID %d", v.instruction, v.id)
      else
        summary = string.format("feedback from ID %d%s", v.id, (v.errors ~= "" and (" (" .. v.errors .. ")") or ""))
      end
      if v.register ~= nil then summary = summary .. " " .. v.register end
      local t = tree:add(zap_proto, range, "mightyZAP " .. summary)
      t:add(ZAP_F.frame, range)
      t:add(ZAP_F.dir, item.dir)
      for _, kv in ipairs(item.values) do
        local f = ZAP_F[kv[1]]
        if f ~= nil and kv[2] ~= nil then t:add(f, kv[2]) end
      end
      t:add(ZAP_F.checksum, item.bytes[item.len - 1])
      t:add(ZAP_F.checksum_ok, true)
      add_links(t, ZAP_F, item, v.kind == "command", ZAP_STATE.response_of, pinfo, ex_zap_nopair)
      info[#info + 1] = summary
    else
      local t = tree:add(zap_proto, range, "bad mightyZAP packet")
      t:add(ZAP_F.bad, range)
      t:add(ZAP_F.checksum_ok, false)
      t:add_proto_expert_info(ex_zap_chk, string.format("checksum mismatch: expected %02X, found %02X",
                                                         item.expected, item.bytes[item.len - 1]))
      info[#info + 1] = "bad checksum"
    end
  end
  pinfo.cols.info = (#info > 0) and table.concat(info, "; ") or "(part of a packet)"
  return tvb:len()
end

-- mightyZAP over Modbus RTU ------------------------------------------------------------------

-- a field per key of zkzap's Modbus records (MB_FIELD_KINDS, from zkzap.codec.modbus.MODBUS_KEYS)
local MB_F = {
  frame = ProtoField.bytes("zapmodbus.frame", "Modbus RTU frame", base.SPACE),
  crc = ProtoField.uint16("zapmodbus.crc", "crc", base.HEX),
  crc_ok = ProtoField.bool("zapmodbus.crc_ok", "crc_ok"),
  request_in = ProtoField.framenum("zapmodbus.request_in", "request in", base.NONE, frametype.REQUEST),
  response_in = ProtoField.framenum("zapmodbus.response_in", "response in", base.NONE, frametype.RESPONSE),
  bad = ProtoField.bytes("zapmodbus.bad", "bad frame", base.SPACE),
}
for _, kv in ipairs(MB_FIELD_KINDS) do
  local key, kind, abbr = kv[1], kv[2], "zapmodbus." .. kv[1]
  if kind == "hex8" then MB_F[key] = ProtoField.uint8(abbr, key, base.HEX)
  elseif kind == "uint8" then MB_F[key] = ProtoField.uint8(abbr, key)
  elseif kind == "uint16" then MB_F[key] = ProtoField.uint16(abbr, key)
  elseif kind == "uint32" then MB_F[key] = ProtoField.uint32(abbr, key)
  elseif kind == "double" then MB_F[key] = ProtoField.double(abbr, key)
  else MB_F[key] = ProtoField.string(abbr, key) end
end
local mb_fields = {}
for _, f in pairs(MB_F) do mb_fields[#mb_fields + 1] = f end
mb_proto.fields = mb_fields
local ex_mb_crc = ProtoExpert.new("zapmodbus.crc_bad", "Modbus RTU CRC-16 mismatch", expert.group.CHECKSUM,
                                  expert.severity.WARN)
local ex_mb_nopair = ProtoExpert.new("zapmodbus.unpaired", "reply without a request to this ID",
                                     expert.group.SEQUENCE, expert.severity.NOTE)
local ex_mb_exception = ProtoExpert.new("zapmodbus.exception_reply", "exception reply", expert.group.RESPONSE_CODE,
                                        expert.severity.WARN)
mb_proto.experts = {ex_mb_crc, ex_mb_nopair, ex_mb_exception}

-- CRC-16/MODBUS (init 0xFFFF), sent low byte first
local CRC16 = crc_table(0xA001)
local function crc16(buf, first, last)
  local c = 0xFFFF
  for i = first, last do c = bit32.bxor(bit32.rshift(c, 8), CRC16[bit32.band(bit32.bxor(c, buf[i]), 0xFF)]) end
  return c
end

-- the lengths a frame from buf[i] may have (nil: more bytes needed), as zkzap's RtuFramer
local function mb_lengths(buf, i, n)
  local fn = buf[i + 1]
  if fn >= 0x80 then return {5} end
  if fn == 0x03 then
    if i + 2 > n then return nil end
    local c = buf[i + 2]
    if c > 0 and c % 2 == 0 and 5 + c ~= 8 then
      if 5 + c < 8 then return {5 + c, 8} end
      return {8, 5 + c}
    end
    return {8}
  end
  if fn == 0x06 then return {8} end
  if fn == 0x10 then
    if i + 6 > n then
      if i + 7 <= n then return {8} end
      return nil
    end
    local c = buf[i + 6]
    if c > 0 and c % 2 == 0 then return {8, 9 + c} end
    return {8}
  end
  return {}
end

local function mb_scan(buf, aligned)
  local found, i, n = {}, 1, #buf
  if aligned == nil then aligned = true end
  while i + 1 <= n do
    if buf[i] > MB_MAX_ID then
      aligned = false
      i = i + 1
    else
      local lengths = mb_lengths(buf, i, n)
      if lengths == nil then break end
      local hit, waiting = nil, false
      for _, len in ipairs(lengths) do
        if i + len - 1 > n then
          waiting = true
        elseif crc16(buf, i, i + len - 3) == buf[i + len - 2] + 256 * buf[i + len - 1] then
          hit = len
          break
        end
      end
      if hit ~= nil then
        found[#found + 1] = {pos = i, len = hit, ok = true}
        i = i + hit
        aligned = true
      elseif waiting then
        break
      else
        if aligned and #lengths > 0 then
          local len = lengths[1]
          found[#found + 1] = {pos = i, len = len, ok = false,
                               expected = crc16(buf, i, i + len - 3), found = buf[i + len - 2] + 256 * buf[i + len - 1]}
        end
        aligned = false
        i = i + 1
      end
    end
  end
  return found, i, aligned
end

local function mb_word(b, k) return b[k] * 256 + b[k + 1] end

local function mb_name(address)
  local r = MB_REGISTERS[address]
  if r ~= nil then return r.name end
  return tostring(address)
end

local function mb_names(address, count)
  local name = mb_name(address)
  if count ~= nil and count > 1 then name = name .. ".." .. mb_name(address + count - 1) end
  return name
end

local function mb_values(out, address, values)
  if #values == 1 then
    out[#out + 1] = {"value", values[1]}
    local r = MB_REGISTERS[address]
    if r ~= nil and r.scale ~= 1 then
      out[#out + 1] = {"physical", round(values[1] * r.scale, 3)}
      out[#out + 1] = {"unit", r.unit}
    end
  else
    local kv = {}
    for k, v in ipairs(values) do kv[#kv + 1] = mb_name(address + k - 1) .. "=" .. v end
    out[#out + 1] = {"values", table.concat(kv, ";")}
  end
end

-- a request's meaning (as zkzap.codec.modbus.Request): address, count, values, or why malformed
local function mb_request(b, n)
  local fn, body = b[1], n - 4
  if (fn == 0x03 or fn == 0x06) and body == 4 then
    local address, word = mb_word(b, 2), mb_word(b, 4)
    if fn == 0x03 then return {address = address, count = word} end
    return {address = address, count = 1, values = {word}}
  end
  if fn == 0x10 and body >= 5 and b[6] == body - 5 and b[6] % 2 == 0 then
    local r = {address = mb_word(b, 2), count = mb_word(b, 4), values = {}}
    for k = 7, n - 3, 2 do r.values[#r.values + 1] = mb_word(b, k) end
    if #r.values ~= r.count then
      r.malformed = string.format("quantity %d but %d registers of data", r.count, #r.values)
    end
    return r
  end
  if MB_FUNCTION_TITLES[fn] ~= nil then
    return {malformed = string.format("%d data bytes do not make a %s request", body, MB_FUNCTION_TITLES[fn])}
  end
  return {malformed = string.format("function 0x%02X is not one the actuator knows", fn)}
end

-- request, reply or exception: by the direction when known, else by the frame's shape
local function mb_kind(b, n, dir)
  local fn = b[1]
  if fn >= 0x80 then return "exception" end
  if dir == 2 then return "request" end
  if dir == 1 then return "reply" end
  if fn == 0x03 then
    if n == 8 and n - 5 ~= b[2] then return "request" end
    return "reply"
  end
  if fn == 0x10 then
    if n == 8 then return "reply" end
    return "request"
  end
  return "request"
end

local function same_bytes(a, b, n)
  if a == nil or a.n ~= n then return false end
  for k = 0, n - 1 do if a[k] ~= b[k] then return false end end
  return true
end

-- the record zkzap's decoder makes of a checked frame; pending: the last request to its ID
local function mb_decode(b, n, dir, st)
  local ident, fn = b[0], bit32.band(b[1], 0x7F)
  local req = st.request[ident]
  if dir == 1 and same_bytes(req, b, n) then dir = 0 end     -- the adapter's echo of the request
  local kind = mb_kind(b, n, dir)
  if kind == "request" and dir == 0 and b[1] == 0x06 and same_bytes(req, b, n) then kind = "reply" end
  local out = {}
  if kind == "request" then
    st.request[ident] = b
    req = nil
  else
    st.request[ident] = nil
    if kind ~= "exception" and req ~= nil then kind = "reply" end
  end
  out[#out + 1] = {"kind", kind}
  out[#out + 1] = {"id", ident}
  out[#out + 1] = {"function", MB_FUNCTIONS[fn] or string.format("0x%02x", fn)}
  out[#out + 1] = {"code", b[1]}
  if kind == "exception" then
    local e = MB_EXCEPTIONS[b[2]]
    out[#out + 1] = {"exception", b[2]}
    out[#out + 1] = {"name", e and e.name or string.format("undocumented-0x%02x", b[2])}
    out[#out + 1] = {"meaning", e and e.meaning or string.format("exception code 0x%02X (not documented)", b[2])}
    return out, kind
  end
  if kind == "request" then
    local r = mb_request(b, n)
    if r.malformed ~= nil then
      out[#out + 1] = {"malformed", r.malformed}
      out[#out + 1] = {"params", hex(b, 2, n - 3)}
      return out, kind
    end
    out[#out + 1] = {"address", r.address}
    out[#out + 1] = {"register", mb_names(r.address, r.count)}
    out[#out + 1] = {"count", r.count}
    if r.values ~= nil then mb_values(out, r.address, r.values) end
    return out, kind
  end
  if fn == 0x03 then
    local values = {}
    for k = 3, n - 3, 2 do values[#values + 1] = mb_word(b, k) end
    local r = req ~= nil and req[1] == 0x03 and mb_request(req, req.n) or nil
    if r ~= nil and r.malformed == nil and r.count == #values then
      out[#out + 1] = {"address", r.address}
      out[#out + 1] = {"register", mb_names(r.address, r.count)}
      mb_values(out, r.address, values)
    else
      out[#out + 1] = {"count", #values}
      if #values == 1 then
        out[#out + 1] = {"value", values[1]}
      else
        local t = {}
        for _, v in ipairs(values) do t[#t + 1] = tostring(v) end
        out[#out + 1] = {"values", table.concat(t, ",")}
      end
    end
    return out, kind
  end
  local address = mb_word(b, 2)
  out[#out + 1] = {"address", address}
  if fn == 0x06 then
    out[#out + 1] = {"register", mb_names(address, 1)}
    mb_values(out, address, {mb_word(b, 4)})
  else
    local count = mb_word(b, 4)
    out[#out + 1] = {"count", count}
    out[#out + 1] = {"register", mb_names(address, count)}
  end
  return out, kind
end

function mb_proto.dissector(tvb, pinfo, tree)
  pinfo.cols.protocol = "mightyZAP Modbus"
  local res = results[pinfo.number]
  local st = MB_STATE
  if res == nil then
    res = first_pass("zapmodbus", mb_scan, tvb, pinfo, function(item, b, dir)
      if not item.ok then return end
      local values, kind = mb_decode(b, item.len, dir, st)
      item.values, item.kind = values, kind
      local ident = b[0]
      if kind == "request" then
        -- (an echo read back is inbound: no request of its own)
        if dir ~= 1 and ident ~= 0 then pair_request(st, ident, pinfo) end
      else
        pair_reply(st, item, ident, pinfo)
      end
      if dir == 1 then item.dir = "d2h" elseif dir == 2 then item.dir = "h2d" end
    end)
  end
  local info = {}
  for _, item in ipairs(res) do
    local range = item_range(tvb, item, "reassembled Modbus RTU frame")
    if item.ok then
      local v = {}
      for _, kv in ipairs(item.values) do v[kv[1]] = kv[2] end
      local summary
      if item.kind == "request" then
        summary = string.format("%s to ID %d", v["function"], v.id)
      elseif item.kind == "exception" then
        summary = string.format("exception %s from ID %d", v.name, v.id)
      else
        summary = string.format("%s reply from ID %d", v["function"], v.id)
      end
      if v.register ~= nil then summary = summary .. " " .. v.register end
      if v.value ~= nil then summary = summary .. "=" .. v.value end
      local t = tree:add(mb_proto, range, "mightyZAP Modbus RTU " .. summary)
      t:add(MB_F.frame, range)
      if item.dir ~= nil then t:add(MB_F.dir, item.dir) end
      for _, kv in ipairs(item.values) do
        local f = MB_F[kv[1]]
        if f ~= nil and kv[2] ~= nil then t:add(f, kv[2]) end
      end
      t:add(MB_F.crc, item.bytes[item.len - 2] + 256 * item.bytes[item.len - 1])
      t:add(MB_F.crc_ok, true)
      if item.kind == "exception" then t:add_proto_expert_info(ex_mb_exception, v.meaning) end
      add_links(t, MB_F, item, item.kind == "request", st.response_of, pinfo, ex_mb_nopair)
      info[#info + 1] = summary
    else
      local t = tree:add(mb_proto, range, "bad Modbus RTU frame")
      t:add(MB_F.bad, range)
      t:add(MB_F.crc_ok, false)
      t:add_proto_expert_info(ex_mb_crc, string.format("CRC-16 mismatch: expected %04X, found %04X",
                                                        item.expected, item.found))
      info[#info + 1] = "bad CRC"
    end
  end
  pinfo.cols.info = (#info > 0) and table.concat(info, "; ") or "(part of a frame)"
  return tvb:len()
end

local encap = DissectorTable.get("wtap_encap")
local encaps = wtap_encaps or wtap
encap:add(encaps.USER0, zk_proto)       -- link type 147
encap:add(encaps.USER1, zap_proto)      -- link type 148
encap:add(encaps.USER2, mb_proto)       -- link type 149
