from django.urls import include, path

from analysis import views

app_name = "analysis"

# The same pages and data for a model's training and for one of its evaluations.
tab = [
    path("data.json", views.data),
    path("points.bin", views.points),
    path("episode.json", views.episode),
    path("rescore/", views.rescore),
    path("rescorings/<int:rescoring>/", views.rescoring),
]

urlpatterns = [
    path("models/<int:pk>/analysis/", views.page, name="model"),
    path("models/<int:pk>/analysis/", include(tab)),
    path("models/<int:pk>/evaluations/<int:evaluation>/analysis/", views.page, name="evaluation"),
    path("models/<int:pk>/evaluations/<int:evaluation>/analysis/", include(tab)),
]
