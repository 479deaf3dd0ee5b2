# Written by vistream; redraw with: gnuplot latency_bytes_london.gp
set terminal pngcairo size 1000,650 enhanced font 'DejaVu Sans,12' linewidth 1.5
set output 'latency_bytes_london.png'
set encoding utf8
set title 'london: bytes sent along cross-town at 6 km/h, per scheme' font ',14'
set style fill solid 0.8 border -1
set boxwidth 0.6
set grid ytics lc rgb '#d0d0d0'
set xlabel 'streaming scheme'
set ylabel 'data sent to the client (MB = 10^6 bytes)'
set key top left box
set yrange [0:*]
set offsets 0, 0, graph 0.08, 0
plot 'latency_bytes_london.bytes.dat' using 0:2:xtic(1) with boxes lc rgb '#1f77b4' title 'bytes sent (MB)', '' using 0:2:(sprintf('%.2f', $2)) with labels offset 0,1 notitle
