-- POST the same 10,242-vertex OFF mesh (bench/load.sh writes it to $KAC_LOAD_MESH) to /v1/shapes.
dofile(os.getenv("KAC_LOAD_DIR") .. "/report.lua")
local f = assert(io.open(os.getenv("KAC_LOAD_MESH"), "rb"))
local mesh = f:read("*a")
f:close()
wrk.method = "POST"
wrk.path = "/v1/shapes?format=off"
wrk.body = mesh
wrk.headers["Content-Type"] = "model/x-off"
