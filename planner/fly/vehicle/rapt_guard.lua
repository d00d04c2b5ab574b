-- RAPT onboard guard: surfaces the vehicle when the back-seat computer that flies it in GUIDED goes silent.
--
-- Installed by `rapt-plan run --mavlink` at bring-up (MAVLink FTP into the scripts directory, then a
-- scripting restart). It watches one sender's HEARTBEAT (the back-seat: system OWNER_SYSID, component
-- OWNER_COMPID). Once it has heard that sender since the vehicle was armed, and the vehicle is armed in
-- GUIDED, a silence of TIMEOUT_MS (vehicle time) switches it to SURFACE and says so in a STATUSTEXT.
-- It never acts in any other mode (a pilot's, or a failsafe's), never disarms, never writes a parameter.
-- Every second it reports itself as NAMED_VALUE_FLOAT "RAPTGUARD" = VERSION, so bring-up can tell it runs.
-- The values below are written in at install time.

local VERSION = {{version}}
local TIMEOUT_MS = {{timeout_ms}}
local OWNER_SYSID = {{owner_sysid}}
local OWNER_COMPID = {{owner_compid}}

local MODE_GUIDED = 4
local MODE_SURFACE = 9
local HEARTBEAT = 0
local PERIOD_MS = 100
local SEV_CRITICAL, SEV_INFO = 2, 6

local heard_ms = nil -- when the owner's HEARTBEAT last came, since the vehicle was armed
local acted = false -- SURFACE was asked for this silence
local next_report_ms = 0

mavlink:init(1, 20)
mavlink:register_rx_msgid(HEARTBEAT)

-- (system, component, message id) of a mavlink_message_t handed over by the firmware: the layout with a
-- one-byte system id (291 bytes) or the MAVLink 2.1 one with four bytes (299 bytes)
local function sender(msg)
  if #msg >= 299 then
    return string.unpack("<I4", msg, 8), string.unpack("<B", msg, 12), string.unpack("<I3", msg, 13)
  end
  return string.unpack("<B", msg, 8), string.unpack("<B", msg, 9), string.unpack("<I3", msg, 10)
end

local function update()
  local now = millis():toint()
  local armed = arming:is_armed()
  local msg = mavlink:receive_chan()
  while msg do
    local sysid, compid, msgid = sender(msg)
    if msgid == HEARTBEAT and sysid == OWNER_SYSID and compid == OWNER_COMPID and armed then
      heard_ms = now
      acted = false
    end
    msg = mavlink:receive_chan()
  end
  if not armed then
    heard_ms = nil -- a new arming must hear the owner again before the guard acts
    acted = false
  elseif heard_ms and not acted and vehicle:get_mode() == MODE_GUIDED and now - heard_ms > TIMEOUT_MS then
    if vehicle:set_mode(MODE_SURFACE) then
      acted = true
      -- a STATUSTEXT holds 50 characters
      gcs:send_text(SEV_CRITICAL, string.format("RAPT guard: back-seat silent %.0f s, SURFACE", (now - heard_ms) / 1000))
    end
  end
  if now >= next_report_ms then
    gcs:send_named_float("RAPTGUARD", VERSION)
    next_report_ms = now + 1000
  end
  return update, PERIOD_MS
end

gcs:send_text(SEV_INFO, string.format("RAPT guard v%d: watching %d/%d, %.0f s", VERSION, OWNER_SYSID, OWNER_COMPID,
  TIMEOUT_MS / 1000))
return update()
