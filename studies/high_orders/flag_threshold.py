"""Flagged share and unflagged sigma ratios for thresholds rho_max (see flag_records.py)."""
import sys

import numpy as np

F=np.load(sys.argv[1])
B=np.load(sys.argv[2])
ORD=[12,18,24,36]
Ts=[float(t) for t in sys.argv[3].split(",")]
def f(a):
  return " ".join(f"{x:5.2f}" for x in a)
for m,name in enumerate(("OO","IO")):
  for j,n in enumerate(ORD):
    if n==12:
      continue
    for T in Ts:
      rho=F[m,j,:,:,5]
      flag=rho>T
      out=[]
      for c,sc in ((0,2),(1,3)):
        mean=[]
        med=[]
        mean_u=[]
        med_u=[]
        for i in range(6):
          v=F[m,j,:,i,c]
          s=np.where(flag[:,i],B[m,j,:,i,sc],F[m,j,:,i,sc])
          ok=np.isfinite(v)
          sd=np.std(v[ok],ddof=1)
          mean.append(np.mean(s[ok])/sd)
          med.append(np.median(s[ok])/sd)
          u=ok&~flag[:,i]
          sdu=np.std(v[u],ddof=1)
          mean_u.append(np.mean(s[u])/sdu)
          med_u.append(np.median(s[u])/sdu)
        out.append((mean,med,mean_u,med_u))
      fl=100*np.nanmean(flag,axis=0)
      print(f"{name} n={n} T={T:5g} flag% {f(fl)} | f unfl mean {f(out[0][2])} med {f(out[0][3])} | xi unfl mean {f(out[1][2])} med {f(out[1][3])}")
