-- POST distinct spectrum jobs (k varies, so every request is a new job) to /v1/jobs, far past saturation.
dofile(os.getenv("KAC_LOAD_DIR") .. "/report.lua")
local shape = os.getenv("KAC_LOAD_SHAPE")
local n = 0
function request()
  n = n + 1
  local k = 2 + (n * 7919 + math.random(0, 1000000)) % 400
  local tol = string.format("1e-%d", 6 + (n % 5))
  local body = string.format('{"shape_id":"%s","analysis":"spectrum","k":%d,"solver":{"tol":%s}}', shape, k, tol)
  return wrk.format("POST", "/v1/jobs", { ["Content-Type"] = "application/json" }, body)
end
