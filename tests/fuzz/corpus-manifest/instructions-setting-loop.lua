--!memory_kib=256
--!instructions=500000000
--!budget_u--!param.fil}
for i = 1, 6,0 do ioE= require("timer")end
--!i4rultru
return {  }
