import numpy as np, glob, sys
def pts(f):
    L=open(f).read().split('{')[1].split('}')[0].split()
    return np.array(L,float).reshape(-1,2)
E=[list(range(36,42)),list(range(42,48)),list(range(48,68))]
def anchors(p): return [p[i].mean(0) for i in E]
def sim(a0,a1,b0,b1):
    f=complex(*(a1-a0)); t=complex(*(b1-b0)); r=t/f
    def m(p):
        z=complex(*(p-a0))*r
        return np.array([b0[0]+z.real,b0[1]+z.imag])
    return m
def aff(a,b):
    A=np.column_stack([a[1]-a[0],a[2]-a[0]]); B=np.column_stack([b[1]-b[0],b[2]-b[0]]); M=B@np.linalg.inv(A)
    return lambda p: b[0]+M@(p-a[0])
for model in sys.argv[1:2]:
    mean=np.load(model)
    ma=anchors(mean)
    for d in sys.argv[2:]:
        e2=[];e3=[];m2=[]
        for f in sorted(glob.glob(d+'/*.pts')):
            t=pts(f); ta=anchors(t); io=np.linalg.norm(ta[1]-ta[0])
            s=sim(ma[0],ma[1],ta[0],ta[1]); a=aff(ma,ta)
            p2=np.array([s(p) for p in mean]); p3=np.array([a(p) for p in mean])
            e2.append(np.linalg.norm(p2-t,axis=1).mean()/io); e3.append(np.linalg.norm(p3-t,axis=1).mean()/io)
            m2.append(np.linalg.norm(p2[48:68].mean(0)-ta[2])/io)
        print(f"{model.split('/')[-3]:5s} {d.split('main/')[-1]:28s} n={len(e2):3d}  2 clicks: mean {np.mean(e2):.3f} IOD (mouth {np.mean(m2):.3f}, worst {np.max(m2):.3f})  3 clicks: mean {np.mean(e3):.3f} IOD")
